"""Grounded tokens to clauses: one request each ("put the cup on the table", "then go to the
shelf"), in the order the robot should do them.

Splits at punctuation, at connectives ("then", "after that", "once", "while") and at "and"
when a verb follows it ("... and go to ..."), but not at "and" between two mentions ("the
plate and the cup"). "Before X, Y" becomes Y, X; "Y after X" becomes X, Y.
"""

from lexicon import AFTER, BEFORE, CONNECTIVES, VERBS
from mentions import Obj, Zone

PUNCT = {",", ";", ".", ":", "!", "?"}
SENTENCE_END = {".", "!", "?"}


class Clause:
    def __init__(self, items, sentence, sub=None):
        self.items = items
        self.sentence = sentence  # index of the sentence the clause is in
        self.sub = sub  # "before" / "after" when the clause opened with one

    def words(self):
        return [x for x in self.items if isinstance(x, str)]

    def __repr__(self):
        return "Clause(%r%s)" % (self.items, ", " + self.sub if self.sub else "")


def connective_at(items, k):
    """Length of the connective starting at k, 0 if none. A trailing "after that" (nothing
    after it but punctuation) closes its clause instead of opening one."""
    for c in sorted(CONNECTIVES, key=len, reverse=True):
        n = len(c)
        if tuple(x if isinstance(x, str) else None for x in items[k:k + n]) == c:
            rest = items[k + n:k + n + 1]
            if c[-1] == "that" and (not rest or rest[0] in PUNCT):
                return 0
            return n
    return 0


def split(items):
    clauses, cur, sentence, sub = [], [], 0, None

    def close():
        nonlocal cur, sub
        if cur:
            clauses.append(Clause(cur, sentence, sub))
        cur, sub = [], None

    k = 0
    while k < len(items):
        it = items[k]
        if isinstance(it, str) and it in PUNCT:
            close()
            if it in SENTENCE_END:
                sentence += 1
            k += 1
            continue
        n = connective_at(items, k)
        if n:
            close()
            k += n
            continue
        if it == "and" and k + 1 < len(items):
            nxt = items[k + 1]
            if isinstance(nxt, str) and (nxt in VERBS or nxt in {"you", "please"}):
                close()
                k += 1
                continue
        if it in (BEFORE, AFTER) and not (k + 1 < len(items) and items[k + 1] == "that"):
            close()
            sub = it
            k += 1
            continue
        cur.append(it)
        k += 1
    close()
    return reorder([c for c in clauses if has_content(c)])


def has_content(c):
    return any(isinstance(x, (Obj, Zone)) for x in c.items) or any(w in VERBS for w in c.words())


def reorder(clauses):
    """ "Before X, Y": Y first. "Y after X" (not at a sentence start): X first."""
    out = list(clauses)
    i = 0
    while i < len(out):
        c = out[i]
        first_in_sentence = i == 0 or out[i - 1].sentence != c.sentence
        if c.sub == BEFORE and first_in_sentence and i + 1 < len(out) and out[i + 1].sentence == c.sentence:
            out[i], out[i + 1] = out[i + 1], out[i]
            i += 2
            continue
        if c.sub == AFTER and not first_in_sentence:
            out[i - 1], out[i] = out[i], out[i - 1]
        i += 1
    return out
