"""Unit tests of the participant client's parsing and printing (standard library unittest):

    pip install -e ./starter-kit && python3 -m unittest discover -s starter-kit/tests

The end-to-end tests against a real server are in tests/e2e/participant_client.rs.
"""

import io
import json
import os
import unittest
from contextlib import redirect_stderr, redirect_stdout

from kitchen_r_client import cli, view
from kitchen_r_client.api import error_message


class Dates(unittest.TestCase):
    def test_rfc3339_with_fraction_and_offset(self):
        a = view.parse_rfc3339_ms("2026-11-22T23:15:28Z")
        self.assertEqual(view.parse_rfc3339_ms("2026-11-22T23:15:28.25Z"), a + 250)
        self.assertEqual(view.parse_rfc3339_ms("2026-11-23T00:15:28+01:00"), a)
        self.assertEqual(view.parse_rfc3339_ms("1970-01-01T00:00:01Z"), 1000)
        self.assertIsNone(view.parse_rfc3339_ms("garbage"))


class Progress(unittest.TestCase):
    RUNNING = {
        "latest_run": {
            "created_at": "2026-11-22T23:00:00Z",
            "evaluation": {"state": "running", "episodes_done": 2, "episodes_total": 8, "episodes_running": 2},
        }
    }

    def test_eta_is_the_finished_episodes_pace_times_the_episodes_left(self):
        now = view.parse_rfc3339_ms("2026-11-22T23:01:00Z")
        self.assertEqual(view.eta_s(self.RUNNING, now), 180.0)
        self.assertTrue(view.progress_line(self.RUNNING, now).endswith("2/8 episodes done, 2 running, ETA 3m 00s"))

    def test_states(self):
        self.assertEqual(view.state({"latest_run": {"scores": {}}}), "finished")
        self.assertEqual(view.state({"latest_run": None}), "queued")
        self.assertFalse(view.ended(self.RUNNING))


class Errors(unittest.TestCase):
    def test_message_code_and_request_id(self):
        body = json.dumps({"error": "submission 9 not found", "code": "not_found", "request_id": "abc"})
        self.assertEqual(error_message(404, body), "submission 9 not found (HTTP 404) [code not_found, request id abc]")
        self.assertEqual(error_message(502, ""), "the server answered HTTP 502")

    def test_unreachable_server_exits_1_with_a_message(self):
        err = io.StringIO()
        with redirect_stderr(err), redirect_stdout(io.StringIO()):
            code = cli.main(["leaderboard", "--server", "http://127.0.0.1:1"])
        self.assertEqual(code, 1)
        self.assertIn("Error: cannot reach the server at http://127.0.0.1:1", err.getvalue())

    def test_a_missing_token_is_a_usage_error(self):
        env = os.environ.pop("KITCHEN_R_TOKEN", None)
        try:
            with redirect_stderr(io.StringIO()), self.assertRaises(SystemExit) as e:
                cli.main(["submission", "show", "1"])
            self.assertEqual(e.exception.code, 2)
        finally:
            if env is not None:
                os.environ["KITCHEN_R_TOKEN"] = env


class Printing(unittest.TestCase):
    def test_dev_episode_rows_with_task_results_and_links(self):
        v = {
            "id": 3,
            "kind": "policy",
            "split": "dev",
            "team": "t",
            "created_at": "x",
            "latest_run": {
                "id": 4,
                "scores": {"sr": 0.5},
                "evaluation": {
                    "state": "finished",
                    "episodes_done": 1,
                    "episodes_total": 1,
                    "episodes_running": 0,
                    "failure_counts": [{"reason": "time limit of N s reached", "count": 1}],
                    "episodes": [
                        {
                            "key": "dev-0001",
                            "mode": "online",
                            "success_rate": 0.5,
                            "wall_ms": 1500,
                            "attempt": 1,
                            "video_url": "/media/v.mp4",
                            "tasks": [
                                {
                                    "index": 0,
                                    "step": "pick the cup",
                                    "success": True,
                                    "completion_time_s": 3.0,
                                    "failure_reason": "",
                                },
                                {
                                    "index": 1,
                                    "step": "place the cup",
                                    "success": False,
                                    "failure_reason": "time limit of 120 s reached",
                                },
                            ],
                        }
                    ],
                },
            },
        }
        lines = []
        view.print_submission(v, "http://s", out=lines.append)
        text = "\n".join(lines)
        self.assertIn("page: http://s/submissions/3", text)
        self.assertIn("scores: SR = 0.5000", text)
        self.assertIn("task 2  FAILED       place the cup: time limit of 120 s reached", text)
        self.assertIn("video: http://s/media/v.mp4", text)

    def test_a_removed_video_prints_its_note_where_the_link_was(self):
        note = "video removed to keep team t's videos within [video] team_max_bytes (2 GiB)"
        v = {
            "id": 3,
            "kind": "policy",
            "split": "dev",
            "team": "t",
            "created_at": "x",
            "latest_run": {
                "id": 4,
                "scores": {},
                "evaluation": {
                    "state": "finished",
                    "episodes_done": 1,
                    "episodes_total": 1,
                    "episodes_running": 0,
                    "failure_counts": [],
                    "episodes": [
                        {
                            "key": "dev-0001",
                            "mode": "online",
                            "wall_ms": 1,
                            "attempt": 1,
                            "video_note": note,
                            "tasks": [],
                        }
                    ],
                },
            },
        }
        lines = []
        view.print_submission(v, "http://s", out=lines.append)
        self.assertIn("video: " + note, "\n".join(lines))


if __name__ == "__main__":
    unittest.main()
