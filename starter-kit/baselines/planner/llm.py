"""The optional language-model planner: any OpenAI-compatible chat endpoint
(`POST {url}/v1/chat/completions`), as the paper's VLM planner.

Per instruction: a system message with the plan grammar and the scene brief (and, with
`vision`, the scene's top-down image), a few solved dev instructions as in-context examples
(same scene first, then the most similar wording), and the instruction. Decoding is constrained
to valid steps: the request asks for a JSON object whose `plan` items are an enum of the
scene's steps (`response_format` json_schema; servers such as vLLM, llama.cpp or OpenAI apply
it while sampling). The answer is checked again (`steps.check`: grammar and a symbolic run in
the scene); an invalid one is sent back with the reason (`retries` times), then the semantic
parser's plan is used instead.
"""

import base64
import json
import re
import urllib.error
import urllib.request

from .steps import check, valid_steps

SYSTEM = """You are the task planner of a mobile manipulator in a kitchen.
Turn the user's instruction into a plan: a JSON object {"plan": [step, ...]}.
Each step is exactly one of: "move to the <colour> zone", "pick the <object>", "place the <object>".
Rules: the robot starts away from every zone; "pick" needs the robot at the zone where the object is, with an empty gripper; "place" puts the held object down in the zone the robot is at; do not move to the zone the robot is already at. Places named by furniture map to zone colours through the scene description. Plans use colours only.
Scene:
%s
Allowed steps: %s"""


class LlmError(Exception):
    pass


class LlmPlanner:
    def __init__(self, url, model, examples, key=None, shots=6, retries=2, vision=False, timeout=120.0):
        self.url = completions_url(url)
        self.model = model
        self.examples = examples  # [{"scene", "instruction", "plan"}] from the dev split
        self.key = key
        self.shots = shots
        self.retries = retries
        self.vision = vision
        self.timeout = timeout
        self.stats = {"requests": 0, "accepted": 0, "repaired": 0, "fallback": 0}

    def plan(self, instruction, scene, brief, fallback, image=None):
        """(plan, how): how is "llm", "llm-repaired" or "parser" (the fallback)."""
        messages = self.messages(instruction, scene, brief, image)
        for attempt in range(self.retries + 1):
            try:
                content = self.complete(messages, scene)
            except LlmError as e:
                self.stats["fallback"] += 1
                return fallback(), "parser (endpoint: %s)" % e
            plan = parse_answer(content)
            why = check(plan, scene) if plan is not None else "the answer is not a JSON plan"
            if why is None:
                self.stats["accepted" if attempt == 0 else "repaired"] += 1
                return plan, "llm" if attempt == 0 else "llm-repaired"
            messages = messages + [
                {"role": "assistant", "content": content},
                {"role": "user", "content": "That plan is invalid: %s. Answer again with a valid plan." % why},
            ]
        self.stats["fallback"] += 1
        return fallback(), "parser"

    def messages(self, instruction, scene, brief, image):
        system = SYSTEM % (brief.strip(), json.dumps(valid_steps(scene)))
        msgs = [{"role": "system", "content": system}]
        for ex in self.pick_examples(instruction, scene.id):
            msgs.append({"role": "user", "content": ex["instruction"]})
            msgs.append({"role": "assistant", "content": json.dumps({"plan": ex["plan"]})})
        if self.vision and image:
            url = "data:image/png;base64," + base64.b64encode(image).decode("ascii")
            msgs.append(
                {
                    "role": "user",
                    "content": [
                        {"type": "text", "text": instruction},
                        {"type": "image_url", "image_url": {"url": url}},
                    ],
                }
            )
        else:
            msgs.append({"role": "user", "content": instruction})
        return msgs

    def pick_examples(self, instruction, scene_id):
        """Same-scene examples first (their plans use this scene's colours), then by shared words."""
        words = set(re.findall(r"[a-z]+", instruction.lower()))

        def score(ex):
            w = set(re.findall(r"[a-z]+", ex["instruction"].lower()))
            return (ex["scene"] == scene_id, len(words & w) / (len(words | w) or 1))

        ranked = sorted(self.examples, key=score, reverse=True)
        return list(reversed(ranked[: self.shots]))  # the closest example right before the question

    def complete(self, messages, scene):
        schema = {
            "type": "object",
            "properties": {
                "plan": {
                    "type": "array",
                    "items": {"type": "string", "enum": valid_steps(scene)},
                    "minItems": 1,
                    "maxItems": 16,
                }
            },
            "required": ["plan"],
            "additionalProperties": False,
        }
        body = {
            "model": self.model,
            "messages": messages,
            "temperature": 0,
            "response_format": {
                "type": "json_schema",
                "json_schema": {"name": "plan", "strict": True, "schema": schema},
            },
        }
        try:
            answer = self.post(body)
        except LlmError as e:
            if "HTTP 400" not in str(e) and "HTTP 422" not in str(e):
                raise
            # A server without structured outputs: ask again unconstrained; `check` still applies.
            del body["response_format"]
            answer = self.post(body)
        try:
            return answer["choices"][0]["message"]["content"] or ""
        except (KeyError, IndexError, TypeError):
            raise LlmError("the answer has no choices[0].message.content") from None

    def post(self, body):
        self.stats["requests"] += 1
        headers = {"Content-Type": "application/json"}
        if self.key:
            headers["Authorization"] = "Bearer " + self.key
        req = urllib.request.Request(self.url, data=json.dumps(body).encode("utf-8"), headers=headers, method="POST")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as r:
                return json.loads(r.read().decode("utf-8"))
        except urllib.error.HTTPError as e:
            raise LlmError("HTTP %d from %s: %s" % (e.code, self.url, e.read()[:200].decode("utf-8", "replace"))) from e
        except (urllib.error.URLError, OSError, ValueError) as e:
            raise LlmError("cannot use %s: %s" % (self.url, e)) from e


def completions_url(url):
    url = url.rstrip("/")
    if url.endswith("/chat/completions"):
        return url
    if url.endswith("/v1"):
        return url + "/chat/completions"
    return url + "/v1/chat/completions"


def parse_answer(content):
    """The plan in a model's answer: {"plan": [...]} or a bare list, possibly inside prose or a
    code fence."""
    for candidate in (content, *re.findall(r"\{.*\}|\[.*\]", content or "", re.S)):
        try:
            v = json.loads(candidate)
        except (TypeError, ValueError):
            continue
        if isinstance(v, dict):
            v = v.get("plan")
        if isinstance(v, list) and all(isinstance(s, str) for s in v):
            return [s.strip() for s in v]
    return None
