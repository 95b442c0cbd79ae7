"""A scene as the planner knows it: parsed from the English brief the server publishes.

The brief (`GET /api/v1/scenes/{id}/brief`) is the only scene source the parser needs. Its
"Zones:" paragraph gives each zone's colour and the names an instruction may use for it; its
"Objects:" paragraph says which object starts in which zone. Parsing it here keeps the planner
independent of the server's internal scene format: whatever the brief says, the planner knows.
"""

import re


class Scene:
    """Zones (colour -> names) and key objects (name -> starting zone colour)."""

    def __init__(self, scene_id, zones, objects, description=""):
        self.id = scene_id
        self.zones = zones  # {"blue": ["the back counter by the fridge", ...], ...}
        self.objects = objects  # {"red cup": "red", "apple": "yellow", ...}
        self.description = description

    def zone_phrases(self):
        """Every phrase that names a zone, with the zone's colour: names and "the C zone"."""
        out = []
        for colour, names in self.zones.items():
            out.append(("the %s zone" % colour, colour))
            for n in names:
                out.append((n, colour))
        return out

    def object_phrases(self):
        """Every phrase that names an object: its full name and, where it is unambiguous in
        this scene, its head noun alone ("the apple" for the only apple, the red apple)."""
        out = [("the " + o, o) for o in self.objects]
        heads = {}
        for o in self.objects:
            heads.setdefault(o.split()[-1], []).append(o)
        for head, objs in heads.items():
            if len(objs) == 1 and objs[0] != head:
                out.append(("the " + head, objs[0]))
        return out


ZONE_CLAUSE = re.compile(r"the (\w+) zone is (.*)")
OBJECT_CLAUSE = re.compile(r"(.+?) (?:is|are) in the (\w+) zone")


def parse_brief(scene_id, text):
    """Read the brief's paragraphs. Raises ValueError naming what is missing."""
    zones, objects, description = {}, {}, []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("Zones:"):
            for part in line[len("Zones:") :].strip().rstrip(".").split(";"):
                m = ZONE_CLAUSE.match(part.strip())
                if not m:
                    continue
                names = []
                if "also called " in m.group(2):
                    called = m.group(2).split("also called ", 1)[1]
                    names = [n.strip() for n in re.split(r",? or ", called) if n.strip()]
                zones[m.group(1)] = [n.lower() for n in names]
        elif line.startswith("Objects:"):
            body = line[len("Objects:") :].strip().rstrip(".")
            for m in OBJECT_CLAUSE.finditer(body):
                colour = m.group(2)
                for name in re.split(r",? and |, ", m.group(1)):
                    name = name.strip()
                    if name.startswith("and "):
                        name = name[4:]
                    if name.startswith("the "):
                        name = name[4:]
                    if name:
                        objects[name.lower()] = colour
        elif line:
            description.append(line)
    if not zones:
        raise ValueError("scene %s: the brief has no 'Zones:' paragraph" % scene_id)
    if not objects:
        raise ValueError("scene %s: the brief has no 'Objects:' paragraph" % scene_id)
    return Scene(scene_id, zones, objects, " ".join(description))
