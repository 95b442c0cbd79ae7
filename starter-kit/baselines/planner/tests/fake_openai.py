"""A tiny OpenAI-compatible chat endpoint for tests (standard library only).

Modes (how it answers `POST /v1/chat/completions`):
- `first-step`: what constrained decoding leaves a model that knows nothing: {"plan": [the first
  step of the request's json_schema enum]} (a valid one-step plan).
- `invalid-then-valid`: prose first; after the planner's correction message, a valid plan.
- `always-invalid`: a plan with a step outside the grammar, every time.
- `no-structured-outputs`: 400 to any request with `response_format`, else `first-step`.

Run as a script for tests in other languages: `python3 fake_openai.py --mode first-step`
prints `listening PORT` and serves until killed; `GET /requests` answers the requests seen.
"""

import argparse
import json
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer


class FakeOpenAI:
    def __init__(self, mode="first-step"):
        self.mode = mode
        self.requests = []
        fake = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_GET(self):
                if self.path == "/requests":
                    self.answer(200, fake.requests)
                else:
                    self.answer(404, {"error": {"message": "not found"}})

            def do_POST(self):
                body = json.loads(self.rfile.read(int(self.headers.get("Content-Length", 0))) or b"{}")
                if self.path != "/v1/chat/completions":
                    self.answer(404, {"error": {"message": "not found"}})
                    return
                fake.requests.append({"body": body, "authorization": self.headers.get("Authorization")})
                status, content = fake.reply(body)
                if status != 200:
                    self.answer(status, {"error": {"message": content}})
                    return
                self.answer(
                    200,
                    {
                        "id": "fake",
                        "object": "chat.completion",
                        "model": body.get("model"),
                        "choices": [
                            {"index": 0, "finish_reason": "stop", "message": {"role": "assistant", "content": content}}
                        ],
                    },
                )

            def answer(self, status, value):
                data = json.dumps(value).encode("utf-8")
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.server.server_address[1]
        self.url = "http://127.0.0.1:%d" % self.port

    def reply(self, body):
        fmt = body.get("response_format")
        if self.mode == "no-structured-outputs" and fmt:
            return 400, "response_format is not supported"
        if self.mode == "always-invalid":
            return 200, json.dumps({"plan": ["fly to the moon"]})
        if self.mode == "invalid-then-valid" and not any(
            m["role"] == "user" and "invalid" in str(m["content"]) for m in body["messages"]
        ):
            return 200, "Sure! First I would go to the counter."
        steps = first_move_step(body)
        return 200, json.dumps({"plan": [steps]})

    def start(self):
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        return self

    def stop(self):
        self.server.shutdown()
        self.server.server_close()


def first_move_step(body):
    fmt = body.get("response_format")
    if fmt:
        return fmt["json_schema"]["schema"]["properties"]["plan"]["items"]["enum"][0]
    # Without a schema: the first allowed step the system message lists.
    system = body["messages"][0]["content"]
    allowed = json.loads(system.split("Allowed steps: ", 1)[1])
    return allowed[0]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--mode", default="first-step")
    a = p.parse_args()
    fake = FakeOpenAI(a.mode)
    print("listening %d" % fake.port, flush=True)
    try:
        fake.server.serve_forever()
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
