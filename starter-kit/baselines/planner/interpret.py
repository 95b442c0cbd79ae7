"""Clauses to plan steps, by acting them out on a symbolic copy of the scene.

The interpreter keeps where the robot is, what it holds and where each object is, and adds the
steps a plan needs that the instruction leaves implicit (learnt from the dev split's plans):
the robot starts away from every zone, so it moves to an object's zone before picking it;
delivering an object is pick, move, place; a move to the zone the robot is at is left out.
Step strings are the plan grammar's: `move to the <colour> zone`, `pick the <object>`,
`place the <object>`.
"""

from .clauses import split
from .lexicon import (
    CARRY,
    DESTINATION,
    MOVE,
    ONTO,
    ORDER_MARKERS,
    PICK,
    PLACE,
    PUT,
    REPLACE,
    SOURCE,
    SWAP,
    SWAP_PHRASES,
    VIA,
    VIA_FOLLOWUP,
)
from .mentions import Obj, Zone, ground
from .references import resolve


def has(words, phrase):
    n = len(phrase)
    return any(tuple(words[i : i + n]) == phrase for i in range(len(words) - n + 1))


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
        self.last_dest = None  # where the latest delivery went
        self.intent = {}  # object -> the place a clause said it should go
        self.last_clause_delivered = False

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
        self.last_dest = self.robot
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

    def insert_before_last_move(self, colours):
        """ "head for the shelf, but go by the sink first": stops before the latest move."""
        if not self.steps or not self.steps[-1].startswith("move to"):
            return False
        last = self.steps.pop()
        self.robot = None
        for c in colours:
            self.move(c)
        self.steps.append(last)
        self.robot = last[len("move to the ") : -len(" zone")]
        return True

    def insert_vias(self, colours):
        """Stops on the way of the latest delivery: before the move that ended it."""
        k = self.last_place
        if k is None or k == 0 or not self.steps[k - 1].startswith("move to"):
            return False
        dest = self.steps[k - 1]
        moves = ["move to the %s zone" % c for c in colours if "move to the %s zone" % c != dest]
        self.steps[k - 1 : k - 1] = moves
        self.last_place += len(moves)
        return True

    # --- reference resolution ---------------------------------------------------------------
    def zone(self, z, moving=None):
        if z.kind == "zone":
            return z.colour
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
    clauses = split(resolve(ground(instruction, scene)))
    clauses = apply_directives(clauses)
    propagate_carry(clauses)
    prev = None
    for c in summaries_skipped(clauses, w):
        before = w.last_place
        interpret(w, c, same_sentence=(prev is not None and c.sentence == prev.sentence))
        w.last_clause_delivered = w.last_place != before
        prev = c
    return w.steps


def summaries_skipped(clauses, w):
    """ "I want the cup on the table instead of the plate: move the plate to the shelf and
    bring the cup over": the part before the colon says what the end state is, the part after
    how to get there. Keep only the how, remembering where each object should go."""
    out = []
    i = 0
    while i < len(clauses):
        c = clauses[i]
        seg = [x for x in clauses if x.segment == c.segment]
        nxt = [x for x in clauses if x.segment == c.segment + 1]
        said = {o for x in seg for o in x.objects()}
        after = {o for x in nxt if not ({"without", "never", "not"} & set(x.words())) for o in x.objects()}
        if c is seg[0] and c.ends_with_colon and said and said <= after:
            for x in seg:
                interpret(Intent(w), x, same_sentence=False)
            i += len(seg)
            continue
        out.append(c)
        i += 1
    return out


class Intent:
    """A stand-in World that only records where clauses say objects should go."""

    def __init__(self, w):
        self.__dict__["w"] = w

    def __getattr__(self, name):
        if name in ("deliver", "carry", "hold", "put", "move", "insert_vias", "insert_before_last_move"):
            return lambda *a, **k: False
        return getattr(self.w, name)

    def __setattr__(self, name, value):
        setattr(self.w, name, value)


def is_directive(c):
    """ "start with the cup", "the cup first", "the fork before the apple": names the delivery
    to do first, moves nothing."""
    return bool(c.objects()) and not c.zones() and any(c.has(m) for m in ORDER_MARKERS) and not carries(c)


def apply_directives(clauses):
    out = [c for c in clauses]
    for c in clauses:
        if not is_directive(c):
            continue
        name = c.objects()[0]
        movers = [j for j in range(len(out)) if out[j].objects() and not is_directive(out[j])]
        mine = [j for j in movers if name in out[j].objects()]
        if not mine:
            continue
        if movers[0] < mine[0]:
            out.insert(movers[0], out.pop(mine[0]))
        else:
            out[mine[0]].first_obj = name
    return out


def carries(c):
    return any(c.has(p) for p in CARRY)


def propagate_carry(clauses):
    """ "carry it to the counter, then the table, without letting go": the carry said at the
    end covers the earlier clauses of the sentence about the same object, unless they say to
    put it down."""
    for c in clauses:
        c.carry = carries(c)
    for i, c in enumerate(clauses):
        if not c.carry:
            continue
        obj = c.objects()[:1]
        for e in reversed(clauses[:i]):
            if e.sentence != c.sentence or any(w in PUT for w in e.words()):
                break
            if not e.objects():
                continue
            if obj and e.objects() != obj:
                break
            e.carry = True
            obj = obj or e.objects()[:1]


def interpret(w, clause, same_sentence):
    items = clause.items
    words = clause.words()
    objs, zones = [], []  # zones: (Zone, role)
    verb_before_obj = None
    first_verb = None
    for k, it in enumerate(items):
        if isinstance(it, Obj):
            plain = [x if isinstance(x, str) else None for x in items[max(0, k - 2) : k]]
            if plain in (["instead", "of"], ["rather", "than"]):
                continue  # "the cup on the table instead of the plate": not what moves
            if it.name not in objs:
                objs.append(it.name)
            w.mention(it.name)
        elif isinstance(it, Zone):
            zones.append((it, role(items, k, objs)))
        elif isinstance(it, str) and verb_class(it) and not (k and items[k - 1] in {"the", "its", "a"}):
            first_verb = first_verb or verb_class(it)
            if not objs:
                verb_before_obj = verb_class(it)
    if is_directive(clause):
        return
    # With no verb before the object, it is the subject: "the cup goes to the shelf".
    verb = verb_before_obj or ("place" if first_verb == "move" and objs else first_verb)
    if any(clause.has(p) for p in SWAP_PHRASES):
        verb = "swap"
    carry = getattr(clause, "carry", False)
    first = getattr(clause, "first_obj", None)
    # Zones that merely say where an object is, or where it comes from, are not targets.
    targets, vias = [], []
    for z, r in zones:
        colour = w.zone(z, moving=objs[0] if objs else None)
        if colour is None:
            continue
        if r == "source" and objs:
            continue
        if isinstance(r, tuple) and colour == w.loc.get(r[1]):
            continue  # "the cup on the table": where the cup is
        (vias if r == "via" else targets).append(colour)
    destinations = sum(1 for _, r in zones if r == "destination")
    for o in objs:
        if targets:
            w.intent[o] = targets[-1]

    if any(x in REPLACE for x in words) and len(objs) >= 2 and not targets:
        # "replace the plate with the cup" / "the plate is replaced by the cup": the cup moves.
        w.deliver(objs[1], w.loc[objs[0]] or w.orig[objs[0]])
        return
    if clause.has(("the", "same")) and objs and not targets and w.last_dest:
        for o in objs:  # "then do the same with the blue cup"
            w.deliver(o, w.last_dest)
        return
    if verb == "swap" and (len(objs) >= 2 or (len(objs) == 1 and zones)):
        a = objs[0]
        b = objs[1] if len(objs) > 1 else zones[0][0].obj
        if not b or b not in w.loc:
            return
        if first == b:
            a, b = b, a
        to_a = w.orig[a] if w.loc[a] is None else w.loc[a]
        w.deliver(a, w.loc[b] or w.orig[b])
        w.deliver(b, to_a)
        return
    if verb == "pick" and objs and not carry and not ({"take", "taking"} & set(words)):
        # "pick up the cup there": a zone where the object already is says where, not whither.
        targets = [t for t in targets if t != w.loc.get(objs[-1])]
    if objs and vias and not targets and same_sentence and w.last_place is not None and w.held is None:
        # "..., and on the way carry it past the shelf": stops of the delivery just made.
        if w.steps[w.last_place] == "place the %s" % objs[0] and w.insert_vias(vias):
            return
    if objs and (targets or vias):
        if carry or verb == "move":
            for o in objs:
                w.carry(o, vias + targets)
        elif len(objs) == 1 and len(targets) > 1 and destinations == len(targets):
            for t in targets:  # "to the table and back to the shelf": put it down at each
                w.deliver(objs[0], t, vias)
                vias = []
        elif len(objs) > 1 and len(objs) == len(targets):
            pairs = list(zip(objs, targets))
            pairs.sort(key=lambda p: p[0] != first)
            for o, t in pairs:
                w.deliver(o, t)
        else:
            dest = targets[-1] if targets else vias.pop()
            objs.sort(key=lambda o: o != first)
            for o in objs:
                w.deliver(o, dest, vias + targets[:-1])
        return
    if objs:
        if verb in ("move", None) and not carry:
            return
        if verb == "place" and w.held == objs[0] and not carry:
            w.put()
            return
        if verb == "place" and objs[0] in w.intent and ("over" in words or "here" in words):
            w.deliver(objs[0], w.intent[objs[0]])  # "... and bring the cup over"
            return
        if verb == "place" and w.held != objs[0] and "down" in words:
            return
        for o in objs:
            w.hold(o)
        return
    if not first_verb and zones and all(z.kind == "of" for z, _ in zones):
        return  # "wherever the plate is": a description, not a request
    if targets or vias:
        colours = vias + targets
        followup = same_sentence and (any(has(words, p) for p in VIA_FOLLOWUP) or (vias and not targets))
        if followup and w.last_place is not None and w.held is None and w.insert_vias(colours):
            return
        if followup and w.held is not None and w.insert_before_last_move(colours):
            return
        onto = any(has(words, p) for p in ONTO)
        if w.held and not carry and (verb == "place" or (verb is None and onto)):
            for c in colours[:-1]:
                w.move(c)
            w.put(colours[-1])
            return
        from_there = any(r == "source" for _, r in zones)
        # "... to the shelf and then on to the table": a second leg of the same delivery.
        lead = next(i for i, x in enumerate(items) if isinstance(x, Zone))
        linking = {"and", "then", "on", "to", "onto", "back", "again", "first", "next", "from", "there", "finally"}
        again = (
            same_sentence
            and w.last_clause_delivered
            and any(r == "destination" for _, r in zones)
            and all(x in linking for x in items[:lead])
        )
        if verb is None and (onto or from_there or again) and clause.context and not carry:
            w.deliver(clause.context, colours[-1], colours[:-1])
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
    before = [x if isinstance(x, str) else None for x in items[max(0, k - 3) : k]]
    if any(tuple(before[-len(v) :]) == v for v in VIA):
        return "via"
    if before and before[-1] in SOURCE:
        return "source"
    if k >= 2 and isinstance(items[k - 2], Obj) and items[k - 1] in {"on", "in", "at", "from", "off"}:
        return ("locative", items[k - 2].name)
    if k >= 1 and items[k - 1] in DESTINATION:
        return "destination"
    return "target"
