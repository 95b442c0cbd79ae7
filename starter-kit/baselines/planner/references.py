"""Pronouns and place words resolved in the order they are read, before clauses are
reordered: "it" is the object mentioned last; "beside it" the object mentioned before the one
being moved; "there" the place mentioned last; "its place" / "where it was" / "instead" the
starting place of the object mentioned before.
"""

from .lexicon import ITS_PLACE, ORIGINAL, PRONOUNS, RELATIVE, SAME_PLACE
from .mentions import Obj, Zone, ends_with

BOUNDARY = {",", ";", ".", ":", "!", "?", "then"}


def resolve(items):
    out = []
    seen = []  # object names in reading order, with the index in `out` of each mention
    last_zone = None
    k = 0
    while k < len(items):
        it = items[k]
        plain = [x if isinstance(x, str) else None for x in items]
        rest = tuple(plain[k : k + 3])
        hit = next((p for p in sorted(ITS_PLACE, key=len, reverse=True) if rest[: len(p)] == p), None)
        if hit == ("instead",) and clause_has_zone(out):
            k += 1  # "put it on the red zone instead": the place is said
            continue
        if hit:
            ref = other_than_current(out, seen)
            z = Zone("of", obj=ref, original=True) if ref else Zone("zone", colour=None)
            out.append(z)
            k += len(hit)
            continue
        same = next((p for p in SAME_PLACE if rest[: len(p)] == p), None)
        if same and plain[k + len(same) : k + len(same) + 1] != ["as"] and seen:
            ref = other_than_current(out, seen)
            if ref:
                out.append(Zone("of", obj=ref))
                k += len(same)
                continue
        if it == "where" and seen and plain[k + 1 : k + 2] == ["you"]:
            # "where you picked it up", "where you found it": the object's starting place.
            j = next((i for i in range(k + 2, min(k + 6, len(plain))) if plain[i] in PRONOUNS), None)
            if j is not None:
                out.append(Zone("of", obj=seen[-1][0], original=True))
                k = j + 1 + (plain[j + 1 : j + 2] == ["up"])
                continue
        if isinstance(it, Obj):
            seen.append((it.name, len(out)))
            out.append(it)
        elif isinstance(it, Zone):
            out.append(it)
            last_zone = it
        elif it == "there" and (last_zone is not None or seen):
            # "there": the place said last, else where the object said last is.
            out.append(last_zone if last_zone is not None else Zone("of", obj=seen[-1][0]))
        elif it == "that" and tuple(plain[k + 1 : k + 3]) == ("is", "where") and last_zone is not None:
            out.append(last_zone)  # "wherever the plate is, that is where the cup goes"
            k += 3
            continue
        elif it in PRONOUNS and k > 0 and plain[k - 1] == "without":
            out.append(it)  # "come back without it": not a mention of what to move
        elif it in PRONOUNS and seen:
            relative = any(ends_with(plain, k, r) for r in RELATIVE) and not (
                ends_with(plain, k, ("on", "to")) or ends_with(plain, k, ("up", "to"))
            )
            if it == "one" and not relative:
                out.append(it)
            elif relative:
                after = [x for x in plain[k + 1 : k + 4] if x]
                ref = seen[-1][0] if out and out[-1] == "where" else other_than_current(out, seen)
                if ref:
                    out.append(Zone("of", obj=ref, original=any(a in ORIGINAL for a in after)))
                    last_zone = out[-1]
            else:
                out.append(Obj(seen[-1][0], word=it))
        else:
            out.append(it)
        k += 1
    return out


def other_than_current(out, seen):
    """The object mentioned before the one of the current clause ("put the bowl beside it")."""
    if not seen:
        return None
    name, at = seen[-1]
    same_clause = not any(isinstance(x, str) and x in BOUNDARY for x in out[at:])
    if same_clause:
        for n, _ in reversed(seen):
            if n != name:
                return n
        return None
    return name


def clause_has_zone(out):
    for x in reversed(out):
        if isinstance(x, str) and x in BOUNDARY:
            return False
        if isinstance(x, Zone):
            return True
    return False
