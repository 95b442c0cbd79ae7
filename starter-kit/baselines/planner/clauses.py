"""Grounded tokens to clauses (one request each: "put the cup on the table", "then go to the
shelf"), put in the order the robot should carry them out.

Splitting: at punctuation, at connectives ("then", "after that", "once", "while") and at "and"
when a verb follows ("... and go to ..."), not at "and" between two mentions ("the plate and
the cup"). Segments are the parts between ".", ";" and ":".

Ordering, from how English marks time rather than from word order:
- "Before X, Y" does Y, then X; a segment opening with "before that" goes before the segment
  it refers to; "Y, once/after X" does X first.
- A clause saying it comes last ("finish at", "in the end", "eventually") goes to the end.
- A clause saying it comes first ("start by", "first visit", "your first stop") goes to the
  front; "stop by the sink first" after a delivery is a stop on the way, left in place.
- "Start with the cup" / "the cup first" reorders the deliveries it names.
"""

from .lexicon import AFTER, BEFORE, CONNECTIVES, END_MARKERS, FIRST_MARKERS, VERBS
from .mentions import Obj, Zone

PUNCT = {",", ";", ".", ":", "!", "?"}
SEGMENT_END = {".", "!", "?", ";", ":"}
SENTENCE_END = {".", "!", "?"}
PRIOR = {"that", "either", "this", "all", "those", "these", "both", "everything"}


class Clause:
    def __init__(self, items, segment, sentence, sub=None, prior=False, context=None):
        self.items = items
        self.context = context  # the object mentioned last up to the end of this clause
        self.front = False  # "... before all of that": the very first thing to do
        self.ends_with_colon = False  # its segment ends with ":" (a summary, then the how)
        self.segment = segment
        self.sentence = sentence
        self.sub = sub  # "before" / "after" / "once" when the clause opened with one
        self.prior = prior  # opened with "before that": goes before what was said before

    def words(self):
        """The plain words, pronouns included ("hold it")."""
        return [
            x if isinstance(x, str) else x.word for x in self.items if isinstance(x, str) or getattr(x, "word", None)
        ]

    def objects(self):
        return [x.name for x in self.items if isinstance(x, Obj)]

    def zones(self):
        return [x for x in self.items if isinstance(x, Zone)]

    def has(self, phrase):
        w = self.words()
        n = len(phrase)
        return any(tuple(w[i : i + n]) == phrase for i in range(len(w) - n + 1))

    def __repr__(self):
        tags = [t for t in (self.sub, "prior" if self.prior else None) if t]
        return "Clause(%d %r%s)" % (self.segment, self.items, " " + ",".join(tags) if tags else "")


def connective_at(items, k):
    """Length of the connective starting at k, 0 if none. A trailing "after that" (nothing
    after it but punctuation) closes its clause instead of opening one."""
    for c in sorted(CONNECTIVES, key=len, reverse=True):
        n = len(c)
        if tuple(x if isinstance(x, str) else None for x in items[k : k + n]) == c:
            rest = items[k + n : k + n + 1]
            if c[-1] == "that" and (not rest or rest[0] in PUNCT):
                return 0
            return n
    return 0


def split(items):
    clauses, cur = [], []
    segment = sentence = 0
    sub, prior = None, False
    context = None

    def close():
        nonlocal cur, sub, prior
        if cur:
            clauses.append(Clause(cur, segment, sentence, sub, prior, context))
            cur, sub, prior = [], None, False

    k = 0
    while k < len(items):
        it = items[k]
        if isinstance(it, str) and it in PUNCT:
            close()
            if it == ":":
                for c in clauses:
                    if c.segment == segment:
                        c.ends_with_colon = True
            segment += it in SEGMENT_END
            sentence += it in SENTENCE_END
            k += 1
            continue
        if it in (BEFORE,) and k + 1 < len(items) and items[k + 1] in PRIOR:
            # "before that", "before all of that", "before either": refers back. At the end
            # of a clause ("go to the shelf before all of that") it puts that clause first.
            if cur:
                close()
                clauses[-1].front = True
            else:
                prior = True
            k += 2
            while k < len(items) and items[k] in {"of", "that", "this", "all", "those", "it"}:
                k += 1
            continue
        if (
            it in (BEFORE, AFTER)
            and k + 1 < len(items)
            and isinstance(items[k + 1], Obj)
            and (k + 2 >= len(items) or items[k + 2] in PUNCT)
        ):
            cur.append(it)  # "move the fork before the apple": an order of deliveries
            k += 1
            continue
        if (
            it == "when"
            and cur == []
            or it == "once"
            or (it in (BEFORE, AFTER) and not (k + 1 < len(items) and items[k + 1] == "that"))
        ):
            close()
            sub = "once" if it == "when" else it
            k += 1
            continue
        n = connective_at(items, k)
        if n:
            close()
            k += n
            continue
        if it == "and" and k + 1 < len(items):
            nxt = items[k + 1]
            if isinstance(nxt, str) and (nxt in VERBS or nxt in {"you", "please", "finally", "lastly"}):
                close()
                k += 1
                continue
        if isinstance(it, Obj):
            context = it.name
        cur.append(it)
        k += 1
    close()
    clauses = merge_object_lists([c for c in clauses if has_content(c) or c.prior])
    return order(clauses)


def merge_object_lists(clauses):
    """ "collect the red cup and then the blue cup on the shelf": one request for both."""
    out = []
    for c in clauses:
        prev = out[-1] if out else None
        if (
            prev is not None
            and prev.sentence == c.sentence
            and c.sub is None
            and not c.prior
            and prev.objects()
            and not prev.zones()
            and c.items
            and isinstance(c.items[0], Obj)
            and c.zones()
            and not any(w in VERBS for w in c.words())
        ):
            prev.items = prev.items + ["and"] + c.items
            prev.context = c.context
            continue
        out.append(c)
    return out


def has_content(c):
    return any(isinstance(x, (Obj, Zone)) for x in c.items) or any(w in VERBS for w in c.words())


def segments_of(clauses):
    segs = []
    for c in clauses:
        if segs and segs[-1][0].segment == c.segment:
            segs[-1].append(c)
        else:
            segs.append([c])
    return segs


def order(clauses):
    segs = [order_segment(s) for s in segments_of(clauses)]
    # A segment opening with "before that" (or "before X, Y" after an earlier segment) goes
    # before the segment it refers to.
    out = []
    for s in segs:
        if out and (s[0].prior or (s[0].sub == BEFORE and len(s) > 1)):
            head = s[1:] + s[:1] if s[0].sub == BEFORE else s
            out[-1:-1] = [head]
        else:
            out.append(s)
    flat = [c for s in out for c in s if has_content(c)]
    # Explicit first (within its sentence, or of all with "before all of that") and last.
    front = [c for c in flat if c.front]
    flat = [c for c in flat if not c.front]
    by_sentence = []
    for c in flat:
        if by_sentence and by_sentence[-1][0].sentence == c.sentence:
            by_sentence[-1].append(c)
        else:
            by_sentence.append([c])
    flat = []
    for s in by_sentence:
        flat += [c for c in s if says_first(c)] + [c for c in s if not says_first(c)]
    last = [c for c in flat if says_last(c)]
    return front + [c for c in flat if c not in last] + last


def order_segment(s):
    s = list(s)
    # "Before X, Y": Y then X.
    if len(s) > 1 and s[0].sub == BEFORE and not s[0].prior:
        s = [s[1], s[0]] + s[2:]
    # "Y, after X": X first. "Y, once X" at the end of a segment: X first.
    for i in range(1, len(s)):
        if s[i].sub == AFTER and s[i - 1].sub is None:
            s[i - 1], s[i] = s[i], s[i - 1]
            return s
    if len(s) > 1 and s[-1].sub == "once" and not any(c.sub in (AFTER, "once") for c in s[:-1]):
        return s[-1:] + s[:-1]
    return s


def says_last(c):
    """ "finish at", "in the end"; not "the cup should end up on the shelf" (a destination)."""
    if c.objects() and (c.has(("end", "up")) or c.has(("ends", "up"))):
        return False
    return any(c.has(m) for m in END_MARKERS)


def says_first(c):
    """ "start by ...", "first visit ...", "your first stop ...": "first" before the place or
    the verb. "stop by the sink first" (after the place) is a stop on the way instead."""
    if not any(c.has(m) for m in FIRST_MARKERS):
        return False
    words = c.items
    k = next(
        i
        for i, x in enumerate(words)
        if isinstance(x, str) and x in {"first", "start", "begin", "starting", "beginning"}
    )
    mentions = [i for i, x in enumerate(words) if isinstance(x, (Zone, Obj))]
    if not mentions:
        return False
    if any(isinstance(x, Obj) for x in words) and not any(isinstance(x, Zone) for x in words):
        return False  # "start with the cup", "the cup first": an order of deliveries
    return k < mentions[0] or any(isinstance(x, Obj) for x in words)
