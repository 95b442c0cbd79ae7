"""run.py end to end against a fake Kitchen-R API (the real server is the e2e test's job)."""

import io
import json
import os
import tempfile
import threading
import unittest
from contextlib import redirect_stderr
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from fake_openai import FakeOpenAI
from support import BRIEF

from kitchen_r_baselines.planner import run

DEV = [
    {
        "id": "dev-0001",
        "scene": "test_kitchen",
        "instruction": "Put the lemon on the round table.",
        "plan": ["move to the amber zone", "pick the lemon", "move to the grey zone", "place the lemon"],
    },
    {
        "id": "dev-0002",
        "scene": "test_kitchen",
        "instruction": "Go to the workbench.",
        "plan": ["move to the amber zone"],
    },
]
TEST = [{"id": "test-0001", "scene": "test_kitchen", "instruction": "Take the mug to the bench under the window."}]


class FakeKitchen:
    def __init__(self):
        self.paths = []
        fake = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_GET(self):
                fake.paths.append(self.path)
                routes = {
                    "/api/v1/dataset/dev": "".join(json.dumps(d) + "\n" for d in DEV).encode(),
                    "/api/v1/dataset/test": "".join(json.dumps(d) + "\n" for d in TEST).encode(),
                    "/api/v1/scenes/test_kitchen/brief": BRIEF.encode(),
                    "/api/v1/scenes/test_kitchen/topdown.png": b"\x89PNG fake",
                }
                body = routes.get(self.path)
                self.send_response(200 if body is not None else 404)
                self.end_headers()
                self.wfile.write(body or b'{"error": "not found"}')

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = "http://127.0.0.1:%d" % self.server.server_address[1]
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def stop(self):
        self.server.shutdown()
        self.server.server_close()


class RunTest(unittest.TestCase):
    def setUp(self):
        self.kitchen = FakeKitchen()
        self.addCleanup(self.kitchen.stop)
        self.dir = tempfile.mkdtemp()

    def run_planner(self, *extra):
        out = os.path.join(self.dir, "plans.jsonl")
        err = io.StringIO()
        with redirect_stderr(err):
            code = run.main(["--server", self.kitchen.url, "--out", out, *extra])
        with open(out) as f:
            return code, [json.loads(line) for line in f], err.getvalue()

    def test_writes_one_plan_line_per_instruction_and_reads_brief_and_image(self):
        images = os.path.join(self.dir, "img")
        code, lines, err = self.run_planner("--split", "test", "--images", images)
        self.assertEqual(code, 0, err)
        self.assertEqual(
            lines,
            [
                {
                    "id": "test-0001",
                    "plan": ["move to the teal zone", "pick the mug", "move to the amber zone", "place the mug"],
                }
            ],
        )
        self.assertIn("/api/v1/scenes/test_kitchen/topdown.png", self.kitchen.paths)
        self.assertTrue(os.path.exists(os.path.join(images, "test_kitchen.png")))

    def test_dev_reports_the_local_em_estimate(self):
        code, lines, err = self.run_planner("--split", "dev")
        self.assertEqual(code, 0, err)
        self.assertIn("local EM estimate against the public dev plans: 1.000000", err)

    def test_the_llm_path_never_shows_an_instruction_its_own_plan(self):
        fake = FakeOpenAI("first-step").start()
        self.addCleanup(fake.stop)
        code, lines, err = self.run_planner("--split", "dev", "--llm", fake.url, "--model", "m")
        self.assertEqual(code, 0, err)
        self.assertEqual(len(fake.requests), 2)
        for req, d in zip(fake.requests, DEV):
            shown = [m["content"] for m in req["body"]["messages"][1:-1] if m["role"] == "user"]
            self.assertNotIn(d["instruction"], shown)
        self.assertIn('"accepted": 2', err)


if __name__ == "__main__":
    unittest.main()
