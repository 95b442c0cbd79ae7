"""How a submission and the leaderboard are printed: the same lines as the Rust `kitchen-r`.

The ETA is the server's (`eta_s`) when it sends one, else the finished episodes' pace: time
since the run was created, per finished episode, times the episodes left; "now" is the
answer's Date header, so a skewed local clock does not skew it.
"""

import re
import time
from datetime import datetime, timedelta, timezone

ENDED = ("finished", "platform_failed", "cancelled")


def _s(v):
    return v if isinstance(v, str) else "?"


def _j(v):
    """A JSON value as `serde_json` prints it in the Rust CLI (numbers bare, null as null)."""
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"%s"' % v
    return str(v)


def _num(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def state(view):
    run = view.get("latest_run")
    if isinstance(run, dict):
        ev = run.get("evaluation")
        if isinstance(ev, dict) and isinstance(ev.get("state"), str):
            return ev["state"]
        return "finished"
    return "queued"


def ended(view):
    return state(view) in ENDED


def why_not_finished(view):
    if state(view) == "cancelled":
        return " (stopped by the organiser; the quota was given back)"
    ev = (view.get("latest_run") or {}).get("evaluation") or {}
    counts = ev.get("failure_counts") or []
    if counts:
        return "; most frequent failure: %s (%s×)" % (_s(counts[0].get("reason")), _j(counts[0].get("count")))
    return ""


_RFC3339 = re.compile(r"^(\d{4})-(\d\d)-(\d\d)[Tt](\d\d):(\d\d):(\d\d)(?:\.(\d+))?([Zz]|[+-]\d\d:\d\d)$")


def parse_rfc3339_ms(t):
    m = _RFC3339.match(t or "")
    if not m:
        return None
    y, mo, d, h, mi, s = (int(x) for x in m.groups()[:6])
    frac = int((m.group(7) or "0").ljust(3, "0")[:3])
    zone = m.group(8)
    tz = timezone.utc
    if zone not in ("Z", "z"):
        sign = -1 if zone[0] == "-" else 1
        tz = timezone(sign * timedelta(hours=int(zone[1:3]), minutes=int(zone[4:6])))
    dt = datetime(y, mo, d, h, mi, s, tzinfo=tz)
    return int(dt.timestamp()) * 1000 + frac


def duration(secs):
    t = int(round(max(secs, 0.0)))
    if t < 60:
        return "%ds" % t
    if t < 3600:
        return "%dm %02ds" % (t // 60, t % 60)
    return "%dh %02dm" % (t // 3600, (t % 3600) // 60)


def eta_s(view, server_now_ms=None):
    run = view.get("latest_run") or {}
    ev = run.get("evaluation") or {}
    if ev.get("state") not in ("running", "queued"):
        return None
    if _num(ev.get("eta_s")):
        return float(ev["eta_s"])
    done, total = ev.get("episodes_done"), ev.get("episodes_total")
    created = parse_rfc3339_ms(run.get("created_at"))
    if not (_num(done) and _num(total)) or created is None:
        return None
    left = total - done
    if done <= 0 or left <= 0:
        return None
    now = server_now_ms if server_now_ms is not None else int(time.time() * 1000)
    return max(now - created, 0) / 1000.0 / done * left


def progress_line(view, server_now_ms=None):
    ev = (view.get("latest_run") or {}).get("evaluation")
    st = state(view)
    if not isinstance(ev, dict):
        return st
    line = "%s: %s/%s episodes done, %s running" % (
        st,
        _j(ev.get("episodes_done")),
        _j(ev.get("episodes_total")),
        _j(ev.get("episodes_running")),
    )
    if (ev.get("episodes_retrying") or 0) > 0:
        line += ", %s retrying" % _j(ev["episodes_retrying"])
    eta = eta_s(view, server_now_ms)
    if eta is not None:
        line += ", ETA " + duration(eta)
    return line


def scores(sc):
    parts = []
    for key, name in (("em", "EM"), ("sr", "SR"), ("mse", "MSE"), ("m", "M"), ("p", "P")):
        v = (sc or {}).get(key)
        if _num(v):
            parts.append("%s = %.4f" % (name, v))
        elif isinstance(v, str):
            parts.append("%s = %s" % (name, v))
    return ", ".join(parts) if parts else "none yet"


def print_submission(view, server, server_now_ms=None, out=print):
    kind = "policy endpoint" if view.get("kind") == "policy" else "plan file"
    out(
        "submission %s: %s, %s split, team %s, created %s"
        % (_j(view.get("id")), kind, _s(view.get("split")), _s(view.get("team")), _s(view.get("created_at")))
    )
    out("page: %s/submissions/%s" % (server.rstrip("/"), _j(view.get("id"))))
    p = view.get("policy")
    if isinstance(p, dict):
        extra = []
        if p.get("reference") is True:
            extra.append("reference run")
        if _num(p.get("plans")):
            extra.append("with plan submission %s" % p["plans"])
        extra.append("max concurrency %s" % _j(p.get("max_concurrency")))
        if p.get("observations") == "privileged":
            extra.append("privileged observations: ranked on the privileged boards")
        out("policy: %s (%s)" % (_s(p.get("endpoint")), ", ".join(extra)))
    run = view.get("latest_run")
    if not isinstance(run, dict):
        out("state: queued (no scoring run yet)")
        return
    out("run %s: %s" % (_j(run.get("id")), progress_line(view, server_now_ms)))
    out("scores: " + scores(run.get("scores")))
    # A policy run's scores mean what its grasp mode made of the episodes.
    evaluation = run.get("evaluation")
    if isinstance(evaluation, dict) and isinstance(evaluation.get("grasp_mode"), str):
        out("grasp mode: " + evaluation["grasp_mode"])
    if view.get("ranked") is False:
        out("not ranked: " + _s(view.get("unranked_reason")))
    if isinstance(run.get("evaluation"), dict):
        _print_evaluation(run["evaluation"], server, out)
    else:
        _print_instructions(run, view.get("split") == "test", out)


def _print_evaluation(ev, server, out):
    if isinstance(ev.get("finished_at"), str):
        out("finished at " + ev["finished_at"])
    if ev.get("needs_resimulation") is True:
        out("note: the ground truth changed since these episodes ran; scores are the old ones")
    if _num(ev.get("rescored_from_run")):
        out("rescored from the episodes of run %s" % ev["rescored_from_run"])
    counts = ev.get("failure_counts") or []
    if counts:
        out("failures:")
        for c in counts:
            out("  %5s × %s" % (_j(c.get("count")), _s(c.get("reason"))))
    for r in ev.get("retrying") or []:
        out("retrying %s (attempt %s): %s" % (_s(r.get("key")), _j(r.get("attempt")), _s(r.get("last_error"))))
    episodes = ev.get("episodes") or []
    if not episodes:
        if (ev.get("episodes_done") or 0) > 0:
            out("per-episode results are not shown on the test split (aggregate feedback only)")
        return
    width = max([len(_s(x.get("key"))) for x in episodes] + [7])
    out("episodes:")
    out("  %-*s  %-7s  %-11s  %7s  attempt" % (width, "episode", "mode", "result", "wall"))
    for x in episodes:
        if _num(x.get("success_rate")):
            result = "SR %.2f" % x["success_rate"]
        elif _num(x.get("mse")):
            result = "MSE %.4f" % x["mse"]
        elif isinstance(x.get("failure"), str):
            result = "not run"
        else:
            result = "-"
        wall = (x.get("wall_ms") or 0) / 1000.0
        out(
            "  %-*s  %-7s  %-11s  %6.1fs  %s"
            % (width, _s(x.get("key")), _s(x.get("mode")), result, wall, _j(x.get("attempt")))
        )
        _print_tasks(x, out)
        if isinstance(x.get("failure"), str):
            out("      failure: " + x["failure"])
        for k, link in x.items():
            if k.endswith("_note") and isinstance(link, str):
                # In the link's place: why it is gone (a video removed to keep a storage budget).
                out("      %s: %s" % (k[: -len("_note")], link))
            elif k.endswith("_url") and isinstance(link, str):
                out("      %s: %s" % (k[: -len("_url")], server.rstrip("/") + link if link.startswith("/") else link))


def _print_tasks(x, out):
    online = x.get("mode") == "online"
    for t in x.get("tasks") or []:
        if online and t.get("success") is True:
            result = "ok %.1f s" % (t.get("completion_time_s") or 0.0)
        elif online:
            result = "FAILED"
        else:
            result = "MSE %.4f (%s samples)" % (t.get("mse") or 0.0, _j(t.get("mse_samples")))
        reason = t.get("failure_reason") or ""
        # 1-based, as the web pages and videos count tasks; the JSON keeps the 0-based index.
        index = t.get("index")
        number = index + 1 if isinstance(index, int) else _j(index)
        out("      task %-2s %-12s %s%s" % (number, result, _s(t.get("step")), (": " + reason) if reason else ""))


def _print_instructions(run, test, out):
    total, present = run.get("instructions_total"), run.get("instructions_present")
    if _num(total) and _num(present):
        out("instructions: %s of %s have a plan in the file" % (present, total))
    rows = run.get("instructions") or []
    if not rows:
        if test:
            out("per-instruction results are not shown on the test split (aggregate feedback only)")
        return
    width = max([len(_s(r.get("id"))) for r in rows] + [11])
    out("  %-*s  %6s  correct steps" % (width, "instruction", "EM"))
    for r in rows:
        note = "  (no plan in the file)" if r.get("present") is False else ""
        out(
            "  %-*s  %6.4f  %s/%s%s"
            % (width, _s(r.get("id")), r.get("em") or 0.0, _j(r.get("correct_steps")), _j(r.get("total_steps")), note)
        )


_COLUMNS = {
    "control": [("SR", "sr"), ("MSE", "mse")],
    "integrated": [("M", "m"), ("P", "p"), ("SR", "sr"), ("MSE", "mse")],
}


def _cell(v):
    if _num(v):
        return "%.4f" % v
    if isinstance(v, str):
        return v
    return "-"


def _interval(v):
    """A score's 95 % interval (`intervals.<key>`, `[low, high]`) as `[0.5800, 0.9200]`."""
    if isinstance(v, list) and len(v) == 2:
        return "[%s, %s]" % (_cell(v[0]), _cell(v[1]))
    return ""


def print_leaderboard(board, out=print):
    track = board.get("track") if isinstance(board.get("track"), str) else "planning"
    observations = board.get("observations")
    label = ", %s observations" % observations if isinstance(observations, str) else ""
    grasp = board.get("grasp_mode")
    label += ", %s grasp" % grasp if isinstance(grasp, str) else ""
    out("%s track%s, %s split" % (track, label, _s(board.get("split"))))
    rows = board.get("rows") or []
    if not rows:
        out("no submissions yet")
        return
    width = max([len(r["team"]) for r in rows if isinstance(r.get("team"), str)] + [4])
    cols = _COLUMNS.get(track, [("EM", "em")])
    header = "%4s  %-*s" % ("rank", width, "team") + "".join("  %8s  %-18s" % (h, h + " 95 %") for h, _ in cols)
    out("%s  %10s  %-9s  submitted (UTC)" % (header, "submission", "state"))
    for r in rows:
        rank = "base" if r.get("baseline") is True else _j(r.get("rank"))
        line = "%4s  %-*s" % (rank, width, _s(r.get("team")))
        scores, intervals = r.get("scores") or {}, r.get("intervals") or {}
        line += "".join("  %8s  %-18s" % (_cell(scores.get(k)), _interval(intervals.get(k))) for _, k in cols)
        state_ = r.get("state") if isinstance(r.get("state"), str) else "finished"
        out("%s  %10s  %-9s  %s" % (line, _j(r.get("submission_id")), state_, _s(r.get("submitted_at"))))
    if isinstance(board.get("ties"), str):
        out("ties: %s" % board["ties"])
