"""The language-model path against a fake OpenAI-compatible endpoint."""

import unittest

from fake_openai import FakeOpenAI
from support import BRIEF, scene

from kitchen_r_baselines.planner.llm import LlmPlanner, completions_url, parse_answer
from kitchen_r_baselines.planner.steps import check, valid_steps

EXAMPLES = [
    {
        "id": "dev-1",
        "scene": "test_kitchen",
        "instruction": "Put the lemon on the round table.",
        "plan": ["move to the amber zone", "pick the lemon", "move to the grey zone", "place the lemon"],
    },
    {"id": "dev-2", "scene": "other", "instruction": "Go to the blue zone.", "plan": ["move to the blue zone"]},
]
PARSER = ["move to the teal zone", "pick the mug"]


class LlmTest(unittest.TestCase):
    def run_mode(self, mode, **kw):
        fake = FakeOpenAI(mode).start()
        self.addCleanup(fake.stop)
        llm = LlmPlanner(fake.url, "fake-model", EXAMPLES, key="sk-test", **kw)
        plan, how = llm.plan("Pick up the mug.", scene(), BRIEF, lambda: PARSER)
        return fake, llm, plan, how

    def test_a_valid_answer_is_used_and_the_request_constrains_decoding(self):
        fake, llm, plan, how = self.run_mode("first-step")
        self.assertEqual((plan, how), (["move to the teal zone"], "llm"))
        body = fake.requests[0]["body"]
        self.assertEqual(body["model"], "fake-model")
        self.assertEqual(fake.requests[0]["authorization"], "Bearer sk-test")
        enum = body["response_format"]["json_schema"]["schema"]["properties"]["plan"]["items"]["enum"]
        self.assertEqual(enum, valid_steps(scene()))
        # In-context examples, the same scene's first (closest to the question, so last).
        msgs = body["messages"]
        self.assertIn("the teal zone is on the counter", msgs[0]["content"])
        self.assertEqual(msgs[-3]["content"], EXAMPLES[0]["instruction"])
        self.assertEqual(msgs[-1], {"role": "user", "content": "Pick up the mug."})

    def test_an_invalid_answer_is_sent_back_with_the_reason_then_repaired(self):
        fake, llm, plan, how = self.run_mode("invalid-then-valid")
        self.assertEqual(how, "llm-repaired")
        self.assertEqual(len(fake.requests), 2)
        self.assertIn("invalid", fake.requests[1]["body"]["messages"][-1]["content"])

    def test_answers_that_stay_invalid_fall_back_to_the_parser(self):
        fake, llm, plan, how = self.run_mode("always-invalid", retries=1)
        self.assertEqual((plan, how), (PARSER, "parser"))
        self.assertEqual(len(fake.requests), 2)
        self.assertEqual(llm.stats["fallback"], 1)

    def test_a_server_without_structured_outputs_is_asked_again_unconstrained(self):
        fake, llm, plan, how = self.run_mode("no-structured-outputs")
        self.assertEqual(how, "llm")
        self.assertNotIn("response_format", fake.requests[1]["body"])

    def test_an_unreachable_endpoint_falls_back_to_the_parser(self):
        llm = LlmPlanner("http://127.0.0.1:9", "m", EXAMPLES, timeout=2)
        plan, how = llm.plan("Pick up the mug.", scene(), BRIEF, lambda: PARSER)
        self.assertEqual(plan, PARSER)
        self.assertTrue(how.startswith("parser (endpoint:"))

    def test_the_top_down_image_goes_with_the_question_with_vision(self):
        fake = FakeOpenAI("first-step").start()
        self.addCleanup(fake.stop)
        llm = LlmPlanner(fake.url, "m", EXAMPLES, vision=True)
        llm.plan("Pick up the mug.", scene(), BRIEF, lambda: PARSER, image=b"\x89PNG")
        content = fake.requests[0]["body"]["messages"][-1]["content"]
        self.assertTrue(content[1]["image_url"]["url"].startswith("data:image/png;base64,"))


class AnswerTest(unittest.TestCase):
    def test_plans_are_found_in_json_prose_and_fences(self):
        self.assertEqual(parse_answer('{"plan": ["a"]}'), ["a"])
        self.assertEqual(parse_answer('Here:\n```json\n["a", "b"]\n```'), ["a", "b"])
        self.assertIsNone(parse_answer("no plan here"))

    def test_completions_url_accepts_base_v1_or_full_urls(self):
        for u in ("http://h:1", "http://h:1/", "http://h:1/v1", "http://h:1/v1/chat/completions"):
            self.assertEqual(completions_url(u), "http://h:1/v1/chat/completions")


class CheckTest(unittest.TestCase):
    def test_grammar_and_symbolic_execution(self):
        s = scene()
        self.assertIsNone(
            check(["move to the amber zone", "pick the lemon", "move to the teal zone", "place the lemon"], s)
        )
        self.assertIn("not one of the allowed", check(["move to the red zone"], s))
        self.assertIn("not in the zone", check(["move to the grey zone", "pick the lemon"], s))
        self.assertIn("does not hold", check(["move to the grey zone", "place the spoon"], s))
        self.assertIn("while holding", check(["move to the teal zone", "pick the mug", "pick the green bottle"], s))


if __name__ == "__main__":
    unittest.main()
