"""The semantic parser's pieces: grounding, clauses and their order, and the interpreter."""

import unittest

from support import scene

from kitchen_r_baselines.planner.clauses import split
from kitchen_r_baselines.planner.interpret import plan
from kitchen_r_baselines.planner.mentions import Obj, Zone, ground
from kitchen_r_baselines.planner.references import resolve


def colours(items):
    return [x.colour for x in items if isinstance(x, Zone)]


class GroundingTest(unittest.TestCase):
    def test_zones_by_colour_and_by_furniture_name(self):
        items = ground("Take the mug from the pantry counter to the grey zone.", scene())
        self.assertEqual(colours(items), ["teal", "grey"])
        self.assertEqual([x.name for x in items if isinstance(x, Obj)], ["mug"])

    def test_a_reworded_furniture_name_still_grounds(self):
        self.assertEqual(colours(ground("wait at the counter near the door", scene())), ["teal"])

    def test_a_plural_colour_list_is_one_zone_each(self):
        self.assertEqual(colours(ground("Visit the grey, amber and teal zones.", scene())), ["grey", "amber", "teal"])

    def test_an_object_after_next_to_is_a_place(self):
        items = ground("Put the lemon next to the spoon.", scene())
        self.assertEqual([(x.kind, x.obj) for x in items if isinstance(x, Zone)], [("of", "spoon")])


class ClauseTest(unittest.TestCase):
    def clauses(self, text):
        return [
            [x.colour if isinstance(x, Zone) else x.name if isinstance(x, Obj) else x for x in c.items]
            for c in split(resolve(ground(text, scene())))
        ]

    def test_and_between_mentions_stays_in_one_clause_and_before_a_verb_splits(self):
        self.assertEqual(len(self.clauses("Put the mug and the lemon on the grey zone.")), 1)
        self.assertEqual(len(self.clauses("Put the mug on the grey zone and go to the amber zone.")), 2)

    def test_before_and_after_put_clauses_in_the_order_of_doing(self):
        c = self.clauses("Before you take the lemon to the grey zone, go to the teal zone.")
        self.assertEqual(c[0], ["go", "to", "teal"])
        c = self.clauses("Go to the teal zone after putting the lemon on the grey zone.")
        self.assertIn("lemon", c[0])

    def test_a_clause_that_says_finish_goes_last(self):
        c = self.clauses("Finish at the amber zone; before that, put the mug on the grey zone.")
        self.assertEqual(c[-1][0], "finish")


class InterpretTest(unittest.TestCase):
    def test_delivery_adds_the_move_and_pick_the_plan_grammar_needs(self):
        self.assertEqual(
            plan("Put the lemon on the round table.", scene()),
            ["move to the amber zone", "pick the lemon", "move to the grey zone", "place the lemon"],
        )

    def test_carry_keeps_the_object_in_hand(self):
        self.assertEqual(
            plan("Grab the spoon and take it with you to the workbench.", scene()),
            ["move to the grey zone", "pick the spoon", "move to the amber zone"],
        )

    def test_swap_uses_the_first_objects_starting_place(self):
        self.assertEqual(
            plan("Swap the lemon and the spoon.", scene()),
            [
                "move to the amber zone",
                "pick the lemon",
                "move to the grey zone",
                "place the lemon",
                "pick the spoon",
                "move to the amber zone",
                "place the spoon",
            ],
        )

    def test_stops_on_the_way(self):
        self.assertEqual(
            plan("Carry the mug to the workbench by way of the round table.", scene()),
            [
                "move to the teal zone",
                "pick the mug",
                "move to the grey zone",
                "move to the amber zone",
                "place the mug",
            ],
        )

    def test_its_place_is_where_the_object_before_it_started(self):
        self.assertEqual(
            plan("Move the lemon to the teal zone and put the spoon in its place.", scene()),
            [
                "move to the amber zone",
                "pick the lemon",
                "move to the teal zone",
                "place the lemon",
                "move to the grey zone",
                "pick the spoon",
                "move to the amber zone",
                "place the spoon",
            ],
        )

    def test_beside_it_refers_to_the_other_object(self):
        self.assertEqual(
            plan("Take the lemon to the teal zone, once the spoon is sitting beside it.", scene()),
            [
                "move to the grey zone",
                "pick the spoon",
                "move to the amber zone",
                "place the spoon",
                "pick the lemon",
                "move to the teal zone",
                "place the lemon",
            ],
        )

    def test_a_start_with_directive_orders_two_deliveries(self):
        self.assertEqual(
            plan("Put the mug and the lemon on the grey zone; start with the lemon.", scene())[:2],
            ["move to the amber zone", "pick the lemon"],
        )

    def test_a_move_to_where_the_robot_is_is_left_out(self):
        self.assertEqual(
            plan("Go to the teal zone, then pick up the mug.", scene()), ["move to the teal zone", "pick the mug"]
        )


if __name__ == "__main__":
    unittest.main()
