"""Clauses to plan steps, by acting them out on a symbolic copy of the scene.

The interpreter keeps where the robot is, what it holds and where each object is, and adds the
steps a plan needs that the instruction leaves implicit (learnt from the dev split's plans):
the robot starts away from every zone, so it moves to an object's zone before picking it;
delivering an object is pick, move, place; a move to the zone the robot is at is left out.
Step strings are the plan grammar's: `move to the <colour> zone`, `pick the <object>`,
`place the <object>`.
"""

from clauses import split
from lexicon import CARRY, ITS_PLACE, MOVE, ONTO, PICK, PLACE, PRONOUNS, SOURCE, SWAP, VIA, VIA_FOLLOWUP
from mentions import Obj, Zone, ground


def has(words, phrase):
    n = len(phrase)
    return any(tuple(words[i:i + n]) == phrase for i in range(len(words) - n + 1))


class World:
    def __init__(self, scene):
        self.scene = scene
        self.robot = None
        self.held = None
        self.loc = dict(scene.objects)
        self.orig = dict(scene.objects)
        self.last_obj = None
        self.prev_obj = None  # the object mentioned before last_obj
        self.last_zone = None
        self.steps = []
        self.last_place = None  # index in steps of the latest `place`

    # --- steps -----------------------------------------------------------------------------
    def move(self, colour):
        if colour and colour != self.robot:
            self.steps.append("move to the %s zone" % colour)
            self.robot = colour

    def hold(self, obj):
        if self.held == obj:
            return
        if self.held is not None:
            self.put()
        self.move(self.loc[obj])
        self.steps.append("pick the %s" % obj)
        self.held = obj
        self.loc[obj] = None

    def put(self, colour=None):
        if self.held is None:
            return
        self.move(colour or self.robot)
        self.steps.append("place the %s" % self.held)
        self.loc[self.held] = self.robot
        self.last_place = len(self.steps) - 1
        self.held = None

    def deliver(self, obj, colour, vias=()):
        if self.held != obj and self.loc.get(obj) == colour:
            return  # already there
        self.hold(obj)
        for v in vias:
            self.move(v)
        self.put(colour)

    def carry(self, obj, colours):
        self.hold(obj)
        for c in colours:
            self.move(c)

    def insert_vias(self, colours):
        """Stops on the way of the latest delivery: before the move that ended it."""
        k = self.last_place
        if k is None or k == 0 or not self.steps[k - 1].startswith("move to"):
            return False
        dest = self.steps[k - 1]
        moves = ["move to the %s zone" % c for c in colours if "move to the %s zone" % c != dest]
        self.steps[k - 1:k - 1] = moves
        self.last_place += len(moves)
        return True

    # --- reference resolution ---------------------------------------------------------------
    def obj(self, it):
        if isinstance(it, Obj):
            return it.name
        return self.last_obj  # a pronoun

    def zone(self, z, moving=None):
        if z.kind == "zone":
            return z.colour
        if z.kind == "there":
            return self.last_zone
        if z.kind == "its":
            ref = self.prev_obj if moving == self.last_obj else self.last_obj
            return self.orig.get(ref) if ref else None
        name = z.obj or self.last_obj
        cur = self.loc.get(name) or self.robot
        # "the plate where the red cup is now": after the cup moved, its old place is meant.
        if z.original or (moving and cur == self.loc.get(moving) and name != moving):
            return self.orig.get(name)
        return cur

    def mention(self, obj):
        if obj and obj != self.last_obj:
            self.prev_obj, self.last_obj = self.last_obj, obj


def plan(instruction, scene):
    """The plan steps for one instruction in one scene."""
    w = World(scene)
    prev_sentence = None
    for c in split(resolve_markers(ground(instruction, scene))):
        interpret(w, c, same_sentence=(c.sentence == prev_sentence))
        prev_sentence = c.sentence
    return w.steps


def resolve_markers(items):
    """Words that stand for places: "there", "its place", "where it was"."""
    out = []
    k = 0
    while k < len(items):
        it = items[k]
        rest = tuple(x if isinstance(x, str) else None for x in items[k:k + 3])
        hit = next((p for p in sorted(ITS_PLACE, key=len, reverse=True) if rest[:len(p)] == p), None)
        if hit:
            out.append(Zone("its"))
            k += len(hit)
            continue
        if it == "there":
            out.append(Zone("there"))
        elif it == "where" and k + 1 < len(items) and items[k + 1] in PRONOUNS:
            after = [x for x in items[k + 2:k + 5] if isinstance(x, str)]
            from lexicon import ORIGINAL
            out.append(Zone("of", obj=None, original=any(a in ORIGINAL for a in after)))
            k += 2
            continue
        else:
            out.append(it)
        k += 1
    return out


def interpret(w, clause, same_sentence):
    items = clause.items
    words = clause.words()
    objs, zones = [], []  # zones: (Zone, role)
    verb_before_obj = None
    first_verb = None
    for k, it in enumerate(items):
        if isinstance(it, Obj) or (it in PRONOUNS and not (k + 1 < len(items) and items[k + 1] == "'s")):
            if isinstance(it, str) and (w.last_obj is None or objs):
                continue
            objs.append(w.obj(it))
            w.mention(objs[-1])
        elif isinstance(it, Zone):
            zones.append((it, role(items, k, objs)))
        elif isinstance(it, str) and verb_class(it):
            first_verb = first_verb or verb_class(it)
            if not objs:
                verb_before_obj = verb_class(it)
    # With no verb before the object, it is the subject: "the cup goes to the shelf".
    verb = verb_before_obj or ("place" if first_verb == "move" and objs else first_verb)
    carry = any(has(words, p) for p in CARRY)
    objs = [o for o in objs if o]
    # Zones that merely say where an object is, or where it comes from, are not targets.
    targets, vias = [], []
    for z, r in zones:
        colour = w.zone(z, moving=objs[0] if objs else None)
        if colour is None:
            continue
        if r == "source" and objs:
            continue
        if r == "locative" and objs and colour == w.loc.get(objs[-1]):
            continue
        (vias if r == "via" else targets).append(colour)
        w.last_zone = colour

    if verb == "swap" and len(objs) >= 2:
        a, b = objs[0], objs[1]
        to_a = w.orig[a] if w.loc[a] is None else w.loc[a]
        w.deliver(a, w.loc[b])
        w.deliver(b, to_a)
        return
    if verb == "pick" and objs and not carry and not ({"take", "taking"} & set(words)):
        # "pick up the cup there": a zone where the object already is says where, not whither.
        targets = [t for t in targets if t != w.loc.get(objs[-1])]
    if objs and (targets or vias):
        if carry or verb == "move":
            for o in objs:
                w.carry(o, vias + targets)
        elif len(objs) > 1 and len(objs) == len(targets):
            for o, t in zip(objs, targets):
                w.deliver(o, t)
        else:
            dest = targets[-1] if targets else vias.pop()
            for o in objs:
                w.deliver(o, dest, vias + targets[:-1])
        return
    if objs:
        if verb in ("move", None) or has(words, ("first",)):
            return  # "starting with the plate", "the bowl first": order only
        if verb == "place" and ("down" in words or w.held == objs[0]) and not carry:
            if w.held == objs[0]:
                w.put()
                return
        if verb == "place" and w.held != objs[0] and "down" in words:
            return
        for o in objs:
            w.hold(o)
        return
    if targets or vias:
        colours = vias + targets
        followup = same_sentence and any(has(words, p) for p in VIA_FOLLOWUP)
        if followup and w.last_place is not None and w.held is None and w.insert_vias(colours):
            return
        onto = any(has(words, p) for p in ONTO)
        if w.held and not carry and (verb == "place" or (verb is None and onto)):
            for c in colours[:-1]:
                w.move(c)
            w.put(colours[-1])
            return
        from_there = any(r == "source" for _, r in zones)
        if verb is None and (onto or from_there) and w.last_obj and not carry:
            w.deliver(w.last_obj, colours[-1], colours[:-1])
            return
        for c in colours:
            w.move(c)
        return
    if verb == "place" and "down" in words:
        w.put()


def verb_class(word):
    if word in SWAP:
        return "swap"
    if word in PLACE:
        return "place"
    if word in PICK:
        return "pick"
    if word in MOVE:
        return "move"
    return None


def role(items, k, objs):
    """What a zone mention is to its clause: "via", "source", "locative" (right after an
    object: "the cup on the table") or "target"."""
    before = [x if isinstance(x, str) else None for x in items[max(0, k - 3):k]]
    if any(tuple(before[-len(v):]) == v for v in VIA):
        return "via"
    if before and before[-1] in SOURCE:
        return "source"
    if k >= 2 and isinstance(items[k - 2], Obj) and items[k - 1] in {"on", "in", "at", "from", "off"}:
        return "locative"
    return "target"
