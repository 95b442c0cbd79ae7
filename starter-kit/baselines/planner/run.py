#!/usr/bin/env python3
"""Planning baseline: plans for a split's instructions, from the public API, as a plan file.

    python3 starter-kit/baselines/planner/run.py --split dev --out dev-plans.jsonl
    kitchen-r submit plans dev-plans.jsonl --split dev

Reads `GET /api/v1/dataset/{split}`, and per scene `GET /api/v1/scenes/{id}/brief` and
`/topdown.png`; writes JSON Lines `{"id": ..., "plan": [...]}`. The default planner is the
semantic parser (interpret.py); `--llm URL --model M` asks an OpenAI-compatible endpoint and
falls back to the parser when its answer is not a valid plan. Only what any participant can
fetch is read; on the dev split the public plans give a local EM estimate (and, with `--llm`,
the in-context examples, never the instruction being planned).

Standard library only (Python >= 3.9, as the package declares).
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.planner.run", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import json
import os
import sys
import time

from kitchen_r_client.api import ApiError, Client

from . import interpret
from .scene import parse_brief
from .steps import check


def args_parser():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--server",
        default=os.environ.get("KITCHEN_R_SERVER", "http://127.0.0.1:8080"),
        help="the Kitchen-R server (KITCHEN_R_SERVER; default http://127.0.0.1:8080)",
    )
    p.add_argument("--split", choices=["dev", "test"], required=True)
    p.add_argument("--out", required=True, help="plan file to write (JSON Lines)")
    p.add_argument("--images", help="also save each scene's top-down image here (DIR/<scene>.png)")
    p.add_argument("--limit", type=int, help="plan only the first N instructions")
    p.add_argument(
        "--explain", action="store_true", help="dev: print each instruction whose plan differs from the public one"
    )
    p.add_argument(
        "--llm", metavar="URL", help="OpenAI-compatible endpoint (e.g. http://127.0.0.1:8000); default: the parser only"
    )
    p.add_argument("--model", help="model name for --llm")
    p.add_argument(
        "--llm-key-env",
        default="OPENAI_API_KEY",
        metavar="VAR",
        help="environment variable holding the endpoint's API key, if it needs one (OPENAI_API_KEY)",
    )
    p.add_argument("--shots", type=int, default=6, help="in-context dev examples per request (6)")
    p.add_argument("--retries", type=int, default=2, help="re-asks after an invalid answer before using the parser (2)")
    p.add_argument("--vision", action="store_true", help="send the scene's top-down image with each request")
    return p


def fetch_lines(client, path):
    text = client.request("GET", path).text()
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def instruction_em(plan, truth):
    """The server's EM for one instruction: steps equal at the same index over the true plan's
    length (extra steps never help)."""
    return sum(1 for i, s in enumerate(truth) if i < len(plan) and plan[i] == s) / len(truth)


def main(argv=None):
    a = args_parser().parse_args(argv)
    if a.llm and not a.model:
        print("error: --llm needs --model", file=sys.stderr)
        return 2
    client = Client(a.server)
    started = time.time()
    try:
        items = fetch_lines(client, "/api/v1/dataset/" + a.split)
        dev = items if a.split == "dev" else (fetch_lines(client, "/api/v1/dataset/dev") if a.llm else [])
        if a.limit:
            items = items[: a.limit]
        scenes, briefs, images = {}, {}, {}
        for sid in sorted({d["scene"] for d in items}):
            briefs[sid] = client.request("GET", "/api/v1/scenes/%s/brief" % sid).text()
            scenes[sid] = parse_brief(sid, briefs[sid])
            images[sid] = client.request("GET", "/api/v1/scenes/%s/topdown.png" % sid).body
            if a.images:
                os.makedirs(a.images, exist_ok=True)
                with open(os.path.join(a.images, sid + ".png"), "wb") as f:
                    f.write(images[sid])
    except ApiError as e:
        print("error: %s" % e, file=sys.stderr)
        return 1
    except ValueError as e:
        print("error: %s" % e, file=sys.stderr)
        return 1

    llm = None
    if a.llm:
        from .llm import LlmPlanner

        llm = LlmPlanner(
            a.llm,
            a.model,
            [d for d in dev if d.get("plan")],
            key=os.environ.get(a.llm_key_env),
            shots=a.shots,
            retries=a.retries,
            vision=a.vision,
        )

    ems, invalid, how_counts = [], 0, {}
    with open(a.out, "w", encoding="utf-8") as out:
        for d in items:
            scene = scenes[d["scene"]]

            def parser_plan(d=d, scene=scene):
                return interpret.plan(d["instruction"], scene)

            if llm:
                # Leave-one-out on dev: the instruction being planned is never its own example.
                llm.examples = [e for e in dev if e.get("plan") and e["id"] != d["id"]]
                plan, how = llm.plan(d["instruction"], scene, briefs[d["scene"]], parser_plan, images[d["scene"]])
            else:
                plan, how = parser_plan(), "parser"
            how_counts[how.split(" ")[0]] = how_counts.get(how.split(" ")[0], 0) + 1
            if not plan or check(plan, scene):
                invalid += 1
            if not plan:
                plan = ["move to the %s zone" % next(iter(scene.zones))]  # the file needs a step
            out.write(json.dumps({"id": d["id"], "plan": plan}) + "\n")
            if d.get("plan"):
                ems.append(instruction_em(plan, d["plan"]))
                if a.explain and ems[-1] < 1:
                    print(
                        "%s EM %.2f  %s\n   public %s\n   ours   %s"
                        % (d["id"], ems[-1], d["instruction"], " | ".join(d["plan"]), " | ".join(plan)),
                        file=sys.stderr,
                    )
    summary = "%d plans for %s written to %s in %.1f s (%s)" % (
        len(items),
        a.split,
        a.out,
        time.time() - started,
        ", ".join("%s %d" % kv for kv in sorted(how_counts.items())),
    )
    if invalid:
        summary += "; %d do not execute symbolically" % invalid
    print(summary, file=sys.stderr)
    if llm:
        print("llm: %s" % json.dumps(llm.stats), file=sys.stderr)
    if ems:
        print("local EM estimate against the public dev plans: %.6f" % (sum(ems) / len(ems)), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
