import unittest

from support import BRIEF, scene

from kitchen_r_baselines.planner.scene import parse_brief


class BriefTest(unittest.TestCase):
    def test_zones_names_and_objects_come_from_the_brief(self):
        s = scene()
        self.assertEqual(
            s.zones,
            {
                "teal": ["the pantry counter", "the counter by the door"],
                "amber": ["the workbench", "the bench under the window"],
                "grey": ["the round table", "the table in the corner"],
            },
        )
        self.assertEqual(s.objects, {"mug": "teal", "green bottle": "teal", "lemon": "amber", "spoon": "grey"})

    def test_an_unambiguous_head_noun_names_its_object(self):
        phrases = dict(scene().object_phrases())
        self.assertEqual(phrases["the bottle"], "green bottle")
        self.assertEqual(phrases["the mug"], "mug")

    def test_a_brief_without_zones_is_refused_with_the_reason(self):
        with self.assertRaisesRegex(ValueError, "no 'Zones:'"):
            parse_brief("x", BRIEF.replace("Zones:", "Places:"))


if __name__ == "__main__":
    unittest.main()
