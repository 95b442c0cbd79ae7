"""Instruction text to tokens, with zone and object mentions grounded to the scene.

Zones are named by colour ("the blue zone") or by the furniture names the brief lists ("the
back counter by the fridge"); objects by their names ("the red cup") or, when unambiguous, by
their head noun ("the apple"). Exact phrases are matched first, longest first; a span that
matches no phrase exactly is matched fuzzily on its content words, so a small variation in
wording ("the counter beside the fridge") still grounds.
"""

import re

from .lexicon import ORIGINAL, RELATIVE, SUBJECT

STOP = {"the", "a", "an", "of", "to", "by", "on", "in", "at", "and", "with", "that", "this"}


class Zone:
    """A zone mention. kind: "zone" (colour known), "of" (where an object is), "its" (the
    starting place of the object mentioned before), "there" (the zone mentioned last)."""

    def __init__(self, kind, colour=None, obj=None, original=False):
        self.kind, self.colour, self.obj, self.original = kind, colour, obj, original

    def __repr__(self):
        return "Zone(%s %s%s)" % (self.kind, self.colour or self.obj or "", " orig" if self.original else "")


class Obj:
    """An object mention; `word` is the pronoun it was written as ("it"), if any."""

    def __init__(self, name, word=None):
        self.name = name
        self.word = word

    def __repr__(self):
        return "Obj(%s)" % self.name


def words(text):
    """Lower-case word and punctuation tokens; plural "zones" lists are expanded."""
    text = text.lower().replace("\u2019", "'").replace("'s", " 's")
    text = re.sub(r"[\"()]", " ", text)
    return re.findall(r"[a-z][a-z\-]*|'s|[,;.:!?]", text)


def phrase_tokens(phrase):
    return words(phrase)


def expand_zone_lists(toks, colours):
    """ "the yellow, green and red zones" -> one "the C zone" per colour."""
    out = list(toks)
    i = 0
    while i < len(out):
        if out[i] == "zones":
            j = i - 1
            cols = []
            while j >= 0 and (out[j] in colours or out[j] in {",", "and"}):
                if out[j] in colours:
                    cols.insert(0, out[j])
                j -= 1
            if len(cols) >= 2:
                repl = []
                for k, c in enumerate(cols):
                    if k:
                        repl += [","] if k < len(cols) - 1 else ["and"]
                    repl += ["the", c, "zone"]
                start = j + 1
                if start > 0 and out[start - 1] == "the":
                    start -= 1
                out[start : i + 1] = repl
                i = start + len(repl)
                continue
        i += 1
    return out


def content(tokens):
    return {t.rstrip("s") for t in tokens if t not in STOP and t.replace("-", "").isalpha()}


def ground(text, scene):
    """Tokens with mentions replaced by Zone/Obj items."""
    toks = expand_zone_lists(words(text), set(scene.zones))
    phrases = [(phrase_tokens(p), Zone("zone", colour=c)) for p, c in scene.zone_phrases()]
    phrases += [(phrase_tokens(p), Obj(o)) for p, o in scene.object_phrases()]
    # Also without the leading article ("put it on blue zone").
    phrases += [(p[1:], item) for p, item in phrases if p and p[0] == "the" and len(p) > 2]
    phrases.sort(key=lambda p: -len(p[0]))
    out = []
    i = 0
    while i < len(toks):
        for p, item in phrases:
            if p and toks[i : i + len(p)] == p:
                out.append(item)
                i += len(p)
                break
        else:
            fuzzy = fuzzy_zone(toks, i, scene)
            if fuzzy:
                out.append(fuzzy[0])
                i += fuzzy[1]
            else:
                out.append(toks[i])
                i += 1
    return relative_places(out)


FURNITURE = {"counter", "table", "shelf", "island", "cabinet", "sink", "stove", "fridge", "cupboard", "desk", "bench"}


def fuzzy_zone(toks, i, scene):
    """A zone named with slightly different words: a span starting with "the" that holds at
    least 2/3 of a zone name's content words, its furniture noun among them, and at most one
    word the name lacks ("the counter beside the fridge" for "the counter next to the fridge")."""
    if toks[i] != "the":
        return None
    best = None
    for length in range(2, 9):
        span = toks[i : i + length]
        if len(span) < length or any(not t.isalpha() and t != "-" for t in span):
            break
        c = content(span)
        if not c or not (c & FURNITURE):
            continue
        for colour, names in scene.zones.items():
            for n in names:
                nc = content(phrase_tokens(n))
                if not nc or not (nc & c & FURNITURE):
                    continue
                score = len(c & nc) / len(nc) - 0.1 * len(c - nc)
                if (
                    len(c & nc) / len(nc) >= 0.66
                    and len(c - nc) <= 1
                    and (best is None or (score, length) > (best[0], best[1]))
                ):
                    best = (score, length, colour)
    if best:
        return Zone("zone", colour=best[2]), best[1]
    return None


def ends_with(items, k, phrase):
    """Do the plain words just before index k spell `phrase`?"""
    n = len(phrase)
    if k < n:
        return False
    return tuple(items[k - n : k]) == phrase


def relative_places(items):
    """ "next to the apple", "where the apple used to be": object mentions that name a place."""
    out = []
    for k, it in enumerate(items):
        if isinstance(it, Obj):
            prev = [x if isinstance(x, str) else None for x in items]
            hold = ends_with(prev, k, ("on", "to")) or ends_with(prev, k, ("up", "to"))
            subject = k + 1 < len(items) and items[k + 1] in SUBJECT
            if not hold and not subject and any(ends_with(prev, k, r) for r in RELATIVE):
                after = [x for x in items[k + 1 : k + 4] if isinstance(x, str)]
                original = any(w in ORIGINAL for w in after)
                out.append(Zone("of", obj=it.name, original=original))
                continue
        out.append(it)
    return out
