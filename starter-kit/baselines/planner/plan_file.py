#!/usr/bin/env python3
"""The semantic parser over an instruction file, offline: no server, one plan per instruction.

    python3 starter-kit/baselines/planner/plan_file.py --instructions DIR/test.jsonl \\
        --briefs BRIEFS --out plans.jsonl

Reads JSON Lines `{"id", "scene", "instruction", ...}` (a dataset split's file) and, for each
scene, the brief the server publishes at `/api/v1/scenes/{id}/brief` saved as `BRIEFS/<id>.txt`;
writes JSON Lines `{"id": ..., "plan": [...]}`, the plan file `kitchen-r submit plans` takes.
`kitchen-r dataset audit` runs it to report the parser's EM on a test set (the same parser as
run.py's default, interpret.plan). Standard library only; runs from a checkout without
installing the package.
"""

if __name__ == "__main__" and not __package__:
    # Run as a file: import this folder as the package it belongs to (installed or not), so the
    # audit can run the parser from any checkout.
    import importlib.util
    import os
    import runpy
    import sys

    if importlib.util.find_spec("kitchen_r_baselines") is None:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        spec = importlib.util.spec_from_file_location(
            "kitchen_r_baselines", os.path.join(root, "__init__.py"), submodule_search_locations=[root]
        )
        assert spec is not None and spec.loader is not None, root
        package = importlib.util.module_from_spec(spec)
        sys.modules["kitchen_r_baselines"] = package
        spec.loader.exec_module(package)
    runpy.run_module("kitchen_r_baselines.planner.plan_file", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import json
import os
import sys
from typing import Optional

from . import interpret
from .scene import Scene, parse_brief


def plan_all(items: list[dict], scenes: dict[str, Scene]) -> list[dict]:
    """One `{"id", "plan"}` per instruction; an instruction the parser fails on gets an empty plan."""
    out = []
    for d in items:
        try:
            plan = interpret.plan(d["instruction"], scenes[d["scene"]])
        except Exception:  # noqa: BLE001 - one bad instruction must not cost the whole file
            plan = []
        out.append({"id": d["id"], "plan": plan})
    return out


def main(argv: Optional[list[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--instructions", required=True, help="JSON Lines with id, scene, instruction")
    p.add_argument("--briefs", required=True, help="folder of scene briefs, <scene id>.txt")
    p.add_argument("--out", required=True, help="plan file to write (JSON Lines)")
    a = p.parse_args(argv)
    with open(a.instructions, encoding="utf-8") as f:
        items = [json.loads(line) for line in f if line.strip()]
    scenes = {}
    for sid in sorted({d["scene"] for d in items}):
        with open(os.path.join(a.briefs, sid + ".txt"), encoding="utf-8") as f:
            scenes[sid] = parse_brief(sid, f.read())
    plans = plan_all(items, scenes)
    with open(a.out, "w", encoding="utf-8") as f:
        for r in plans:
            f.write(json.dumps(r) + "\n")
    print("%d plans written to %s" % (len(plans), a.out), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
