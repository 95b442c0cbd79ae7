"""Shared test material: a made-up scene.

The scene is invented (colours, furniture and objects that no shipped scene has), written the
way the server's brief is, so the tests show the parser works from the brief, not from our
scenes or templates.
"""

from kitchen_r_baselines.planner.scene import parse_brief

BRIEF = """A narrow kitchen with a pantry by the door, a workbench under the window and a round table.
Zones: the teal zone is on the counter (0.90 m high), also called the pantry counter or the counter by the door; the amber zone is on the workbench (0.85 m high), also called the workbench or the bench under the window; the grey zone is on the table (0.75 m high), also called the round table or the table in the corner.
Objects: the mug and the green bottle are in the teal zone, the lemon is in the amber zone and the spoon is in the grey zone.
"""


def scene():
    return parse_brief("test_kitchen", BRIEF)
