"""Shared test material: the planner's modules on the path, and a made-up scene.

The scene is invented (colours, furniture and objects that no shipped scene has), written the
way the server's brief is, so the tests show the parser works from the brief, not from our
scenes or templates.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..")))

from scene import parse_brief  # noqa: E402

BRIEF = """A narrow kitchen with a pantry by the door, a workbench under the window and a round table.
Zones: the teal zone is on the counter (0.90 m high), also called the pantry counter or the counter by the door; the amber zone is on the workbench (0.85 m high), also called the workbench or the bench under the window; the grey zone is on the table (0.75 m high), also called the round table or the table in the corner.
Objects: the mug and the green bottle are in the teal zone, the lemon is in the amber zone and the spoon is in the grey zone.
"""


def scene():
    return parse_brief("test_kitchen", BRIEF)
