"""`kitchen-r-client`: the participant commands of the Rust `kitchen-r` CLI.

    kitchen-r-client team create NAME                       (organiser token)
    kitchen-r-client submit plans FILE --split dev|test [--json]
    kitchen-r-client submit policy URL --split dev|test [--plans ID] [--episodes N]
                     [--endpoint-token T] [--key-map JSON|FILE] [--reference]
                     [--wait [--timeout S]] [--json]
    kitchen-r-client submission show ID [--json]
    kitchen-r-client submission wait ID [--timeout S] [--json]
    kitchen-r-client leaderboard [--track T] [--split S] [--observations standard|privileged]
                                 [--grasp-mode abstract|physical] [--format table|json|csv | --json]

Every command takes --server (KITCHEN_R_SERVER, default http://127.0.0.1:8080) and --token
(KITCHEN_R_TOKEN; `team create` reads --admin-token / KITCHEN_R_ADMIN_TOKEN). Exit codes: 0
success; 1 an error (the server's message, error code and request id on stderr) or a run that
ended failed or cancelled; 2 a usage error; 124 `wait --timeout` ran out.
"""

import argparse
import json
import os
import sys
import time

from . import __version__, view
from .api import ApiError, Client

DEFAULT_SERVER = "http://127.0.0.1:8080"
TIMEOUT_EXIT = 124


def _seconds(s):
    try:
        v = float(s)
    except ValueError:
        v = -1.0
    if not (0.0 <= v < 1e9):
        raise argparse.ArgumentTypeError("%r is not a number of seconds (0 or more)" % s)
    return v


class Failure(Exception):
    """An error to print as `Error: ...` with exit code 1 (as the Rust CLI's anyhow errors)."""


def _env_opt(parser, flag, env, help_, required=True):
    value = os.environ.get(env)
    parser.add_argument(
        flag,
        default=value,
        required=required and not value,
        help="%s (env %s)" % (help_, env),
        metavar=flag.lstrip("-").upper().replace("-", "_"),
    )


def _server(parser):
    parser.add_argument(
        "--server",
        default=os.environ.get("KITCHEN_R_SERVER", DEFAULT_SERVER),
        help="server base URL (env KITCHEN_R_SERVER, default %s)" % DEFAULT_SERVER,
    )


def _auth(parser, help_="team token (or the organiser token, which sees every submission)"):
    _server(parser)
    _env_opt(parser, "--token", "KITCHEN_R_TOKEN", help_)


def build_parser():
    p = argparse.ArgumentParser(
        prog="kitchen-r-client", description="Kitchen-R participant client (no Rust build needed)."
    )
    p.add_argument("--version", action="version", version="%(prog)s " + __version__)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    team = sub.add_parser("team", help="organiser: manage teams").add_subparsers(dest="action", metavar="ACTION")
    team.required = True
    create = team.add_parser("create", help="make a team and print its token (shown once)")
    create.add_argument("name")
    _server(create)
    _env_opt(create, "--admin-token", "KITCHEN_R_ADMIN_TOKEN", "organiser token")
    create.set_defaults(func=cmd_team_create)

    submit = sub.add_parser("submit", help="upload a plan file or register a policy endpoint")
    submit = submit.add_subparsers(dest="action", metavar="ACTION")
    submit.required = True
    plans = submit.add_parser("plans", help='upload a plan file (JSON Lines: {"id": ..., "plan": [...]})')
    plans.add_argument("file")
    plans.add_argument("--split", required=True, choices=["dev", "test"])
    plans.add_argument("--json", action="store_true", help="print the server's JSON answer")
    _auth(plans, "team token")
    plans.set_defaults(func=cmd_submit_plans)

    pol = submit.add_parser("policy", help="register a policy endpoint (gRPC or openpi) for evaluation")
    pol.add_argument(
        "endpoint",
        help="gRPC at http://HOST:PORT or https://HOST:PORT, or an openpi WebSocket server at "
        "ws://HOST:PORT or wss://HOST:PORT, reachable from the server",
    )
    pol.add_argument(
        "--key-map",
        metavar="JSON|FILE",
        help="openpi (ws://) endpoints: the key map, inline JSON or a JSON file (default: the documented keys)",
    )
    pol.add_argument("--split", required=True, choices=["dev", "test"])
    pol.add_argument("--plans", type=int, metavar="SUBMISSION_ID", help="integrated track: your plan submission")
    pol.add_argument("--episodes", type=int, metavar="N", help="dev only: the first N instructions")
    _env_opt(
        pol,
        "--endpoint-token",
        "KITCHEN_R_POLICY_TOKEN",
        "bearer token the workers send to your endpoint",
        required=False,
    )
    pol.add_argument("--reference", action="store_true", help="organiser: a reference (baseline) run")
    pol.add_argument("--wait", action="store_true", help="follow the run and print it when it ends")
    pol.add_argument("--timeout", type=_seconds, metavar="SECONDS", help="with --wait: give up after S seconds")
    pol.add_argument("--json", action="store_true", help="print the server's JSON answers")
    _auth(pol, "team token (the organiser token with --reference)")
    pol.set_defaults(func=cmd_submit_policy)

    subm = sub.add_parser("submission", help="a submission's progress and results")
    subm = subm.add_subparsers(dest="action", metavar="ACTION")
    subm.required = True
    show = subm.add_parser("show", help="state, progress with ETA, scores, per-episode rows on dev")
    show.add_argument("id", type=int)
    show.add_argument("--json", action="store_true", help="print the server's JSON view")
    _auth(show)
    show.set_defaults(func=cmd_show)
    wait = subm.add_parser("wait", help="poll until the run ends; exit 0 only if it finished")
    wait.add_argument("id", type=int)
    wait.add_argument("--timeout", type=_seconds, metavar="SECONDS", help="give up after S seconds (exit 124)")
    wait.add_argument("--json", action="store_true", help="print the final JSON view")
    _auth(wait)
    wait.set_defaults(func=cmd_wait)

    lb = sub.add_parser("leaderboard", help="print the ranking")
    lb.add_argument("--track", default="planning", choices=["planning", "control", "integrated"])
    lb.add_argument("--split", default="test", choices=["dev", "test"])
    lb.add_argument(
        "--observations",
        default="standard",
        choices=["standard", "privileged"],
        help="control and integrated: the board of runs whose policy received "
        "privileged observations (ranked apart), or the standard one",
    )
    lb.add_argument(
        "--grasp-mode",
        default=None,
        choices=["abstract", "physical"],
        help="control and integrated: the board of runs evaluated in this grasp mode "
        "(ranked apart); default: the contest's",
    )
    lb.add_argument("--format", default="table", choices=["table", "json", "csv"])
    lb.add_argument("--json", action="store_true", help="same as --format json")
    _server(lb)
    lb.set_defaults(func=cmd_leaderboard)
    return p


def cmd_team_create(a):
    v = Client(a.server).post_json("/api/v1/teams", {"name": a.name}, token=a.admin_token)
    print("team %s created (id %s)" % (v.get("name", "?"), v.get("id")))
    print("token: %s" % v.get("token", "?"))
    print("keep it: it is shown only once; participants pass it as --token or KITCHEN_R_TOKEN")
    return 0


def cmd_submit_plans(a):
    try:
        with open(a.file, "rb") as f:
            body = f.read()
    except OSError as e:
        raise Failure("cannot read %s: %s" % (a.file, e.strerror or e)) from e
    client = Client(a.server, a.token, timeout=120.0)
    v = client.post_json("/api/v1/submissions/plans?split=" + a.split, body, "application/x-ndjson")
    if a.json:
        print(json.dumps(v))
        return 0
    em = (v.get("scores") or {}).get("em")
    em = "%.6f" % em if isinstance(em, (int, float)) else "NaN"
    print("submission %s (%s): EM = %s" % (v.get("id"), a.split, em))
    for w in v.get("warnings") or []:
        print("warning: %s" % w)
    return 0


def _key_map(arg):
    """A key map given inline (starting with `{`) or as a JSON file, as a dict."""
    text = arg
    if not arg.lstrip().startswith("{"):
        try:
            with open(arg) as f:
                text = f.read()
        except OSError as e:
            raise Failure("reading the key map %s: %s" % (arg, e)) from e
    try:
        v = json.loads(text)
    except ValueError as e:
        raise Failure("--key-map is not JSON: %s" % e) from e
    if not isinstance(v, dict):
        raise Failure("--key-map must be a JSON object")
    return v


def cmd_submit_policy(a):
    if a.timeout is not None and not a.wait:
        raise Failure("--timeout needs --wait")
    body = {"endpoint": a.endpoint, "split": a.split}
    if a.plans is not None:
        body["plans"] = a.plans
    if a.episodes is not None:
        body["episodes"] = a.episodes
    if a.endpoint_token:
        body["token"] = a.endpoint_token
    if a.reference:
        body["reference"] = True
    if a.key_map:
        body["key_map"] = _key_map(a.key_map)
    client = Client(a.server, a.token)
    v = client.post_json("/api/v1/submissions/policies", body)
    if a.json and not a.wait:
        print(json.dumps(v))
        return 0
    sid = v.get("id")
    print(
        "submission %s accepted: %s episodes of %s instructions queued (%s, %s observations), policy: %s"
        % (
            sid,
            v.get("episodes"),
            v.get("instructions"),
            a.split,
            v.get("observations", "standard"),
            v.get("policy", "?"),
        ),
        file=sys.stderr,
    )
    if not a.wait:
        print(sid)
        print(
            "follow it with `kitchen-r-client submission wait %s` (or `submission show %s`, or %s)"
            % (sid, sid, client.url("/submissions/%s" % sid)),
            file=sys.stderr,
        )
        return 0
    snap = wait_for(client, sid, a.timeout)
    return finish(snap, a.server, a.json)


def cmd_show(a):
    resp = Client(a.server, a.token).request("GET", "/api/v1/submissions/%d" % a.id)
    v = resp.json()
    if a.json:
        print(json.dumps(v))
    else:
        view.print_submission(v, a.server, resp.server_now_ms())
    return 0


def cmd_wait(a):
    snap = wait_for(Client(a.server, a.token), a.id, a.timeout)
    return finish(snap, a.server, a.json)


def finish(snap, server, as_json):
    v, now = snap
    if as_json:
        print(json.dumps(v))
    else:
        view.print_submission(v, server, now)
    st = view.state(v)
    if st != "finished":
        raise Failure("submission %s: its run ended %s%s" % (v.get("id"), st, view.why_not_finished(v)))
    return 0


class TimedOut(Exception):
    pass


def wait_for(client, sid, timeout=None):
    """Poll until the latest run ends; progress lines on stderr when they change. The interval
    starts at 1 s and grows by half up to 15 s while nothing changes. Unreachable, 5xx and 429
    answers are retried (honouring Retry-After) until the timeout; any other refusal stops."""
    start = time.monotonic()
    interval, last = 1.0, ""
    while True:
        pause = None
        try:
            resp = client.request("GET", "/api/v1/submissions/%d" % sid)
            v, now = resp.json(), resp.server_now_ms()
            if view.ended(v):
                return v, now
            line = view.progress_line(v, now)
            if line != last:
                print("submission %s: %s" % (sid, line), file=sys.stderr, flush=True)
                last, interval = line, 1.0
        except ApiError as e:
            if not e.transient:
                raise
            print("submission %s: %s (retrying)" % (sid, e), file=sys.stderr, flush=True)
            pause = e.retry_after
        sleep = max(pause if pause is not None else interval, 0.2)
        if timeout is not None:
            left = timeout - (time.monotonic() - start)
            if left <= 0:
                raise TimedOut(
                    "submission %s: not finished after %.0f s (last: %s)" % (sid, timeout, last or "no answer")
                )
            sleep = min(sleep, left)
        time.sleep(sleep)
        interval = min(interval * 1.5, 15.0)


def cmd_leaderboard(a):
    fmt = "json" if a.json else a.format
    observations = "" if a.observations == "standard" else "&observations=%s" % a.observations
    if a.grasp_mode:
        observations += "&grasp_mode=%s" % a.grasp_mode
    path = "/api/v1/leaderboard?track=%s&split=%s%s&format=%s" % (
        a.track,
        a.split,
        observations,
        "csv" if fmt == "csv" else "json",
    )
    text = Client(a.server).request("GET", path).text()
    if fmt == "table":
        try:
            board = json.loads(text)
        except ValueError:
            raise Failure("the server's answer is not JSON") from None
        view.print_leaderboard(board)
    elif fmt == "json":
        print(text)
    else:
        sys.stdout.write(text)
    return 0


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except TimedOut as e:
        print("Error: %s" % e, file=sys.stderr)
        return TIMEOUT_EXIT
    except (ApiError, Failure) as e:
        print("Error: %s" % e, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # Output piped into `head`: stop quietly (Python's documented recipe).
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
