"""The parser's small English lexicon: verb classes, connectives and markers.

Nothing here names a template or a dataset sentence: these are ordinary English words for
moving, taking and putting, grouped by what they ask the robot to do. Extend it to cover
phrasings the parser misses (`python3 run.py --split dev --explain` shows where it fails).
"""

# Verbs that ask the robot to go somewhere (with a zone: visit it).
MOVE = {
    "go",
    "goes",
    "going",
    "head",
    "heading",
    "walk",
    "walking",
    "navigate",
    "drive",
    "visit",
    "visiting",
    "stop",
    "stopping",
    "wait",
    "waiting",
    "check",
    "checking",
    "swing",
    "start",
    "starting",
    "continue",
    "finish",
    "finishing",
    "end",
    "ending",
    "come",
    "look",
    "proceed",
    "travel",
    "pass",
    "passing",
    "stay",
    "park",
    "tour",
    "see",
    "find",
    "pop",
}
# Verbs that ask the robot to take hold of an object.
PICK = {
    "pick",
    "picking",
    "grab",
    "grabbing",
    "take",
    "taking",
    "fetch",
    "fetching",
    "get",
    "getting",
    "lift",
    "collect",
    "hold",
    "holding",
    "retrieve",
    "seize",
    "keep",
    "picked",
    "held",
    "grabbed",
    "taken",
    "collected",
    "fetched",
    "lifted",
}
# Verbs that move an object to a place (put it down there).
PLACE = {
    "put",
    "putting",
    "place",
    "placing",
    "set",
    "setting",
    "leave",
    "leaving",
    "left",
    "drop",
    "dropping",
    "move",
    "moves",
    "moved",
    "moving",
    "bring",
    "bringing",
    "carry",
    "carrying",
    "deliver",
    "transfer",
    "clear",
    "remove",
    "relocate",
    "belongs",
    "belong",
    "store",
    "rest",
    "return",
    "returning",
    "placed",
    "dropped",
    "carried",
    "brought",
    "delivered",
    "returned",
    "parade",
    "route",
    "relocated",
    "removed",
}
# Verbs that exchange the places of two objects.
SWAP = {"swap", "trade", "exchange", "switch", "interchange"}

VERBS = MOVE | PICK | PLACE | SWAP

# Words and phrases that end one step of the instruction and start the next.
CONNECTIVES = [
    ("and", "then"),
    ("after", "that"),
    ("and", "after", "that"),
    ("then",),
    ("afterwards",),
    ("afterward",),
    ("while",),
    ("so",),
    ("followed", "by"),
]
# Subordinators that may reorder: "before X, Y" does Y first.
BEFORE = "before"
AFTER = "after"

# Phrases saying the object stays in the gripper (carry, do not place).
CARRY = [
    ("without", "putting"),
    ("without", "letting"),
    ("without", "setting"),
    ("without", "dropping"),
    ("keep", "it"),
    ("in", "hand"),
    ("hold", "on"),
    ("with", "you"),
    ("with", "it"),
    ("on", "a", "tour"),
    ("holding", "it"),
    ("still", "holding"),
    ("hold", "it"),
    ("holding",),
    ("your", "hand"),
    ("never", "put"),
    ("never", "let"),
    ("don't", "put"),
    ("do", "not", "put"),
    ("show", "it"),
    ("kept", "in"),
    ("keep", "holding"),
    ("keeping", "it"),
    ("not", "put", "it", "down"),
    ("in", "your", "gripper"),
    ("never", "setting"),
    ("never", "letting"),
    ("keep", "hold"),
    ("keeps", "hold"),
    ("without", "ever"),
]
# Words before a zone that make it a stop on the way, not the destination.
VIA = [
    ("by", "way", "of"),
    ("via",),
    ("past",),
    ("passing",),
    ("stopping",),
    ("through",),
    ("detouring", "by"),
    ("detour", "by"),
    ("detour", "via"),
    ("detour", "past"),
    ("go", "by"),
    ("carry", "it", "by"),
    ("stopping", "at"),
    ("stopping", "by"),
    ("calling", "at"),
    ("a", "stop", "at"),
    ("route", "it", "past"),
]
# Words in a follow-up clause that make its zones stops on the way of the previous delivery.
VIA_FOLLOWUP = [
    ("on", "the", "way"),
    ("passing",),
    ("stopping",),
    ("first",),
    ("beforehand",),
    ("along", "the", "way"),
    ("en", "route"),
    ("detour",),
    ("past",),
    ("via",),
]
# Words before a zone that make it where the object comes from.
SOURCE = {"from", "off"}
# Words between an object and the zone that merely says where it is ("the cup on the table").
LOCATIVE = {"on", "in", "at", "from", "off"}
# Words before an object mention that make it a place ("next to the apple").
RELATIVE = [
    ("next", "to"),
    ("beside",),
    ("by",),
    ("where",),
    ("wherever",),
    ("near",),
    ("spot", "of"),
    ("same", "spot", "as"),
    ("same", "place", "as"),
    ("the", "spot"),
    ("the", "place"),
    ("over", "to"),
    ("to",),
    ("alongside",),
    ("place", "of"),
    ("position", "of"),
]
# Words after an object mention that make it the subject, not a place ("where the cup belongs").
SUBJECT = {"belongs", "belong", "goes", "go", "should", "needs", "must"}
# Words after such a mention that mean its starting place ("where the apple used to be").
ORIGINAL = {"was", "used", "started", "now", "originally", "before", "initially", "earlier", "left", "vacated", "had"}
# Phrases for the starting place of the object mentioned before ("put the bowl in its place").
ITS_PLACE = [
    ("its", "place"),
    ("its", "old", "place"),
    ("its", "spot"),
    ("instead",),
    ("its", "old", "spot"),
    ("its", "former", "place"),
]
# Words that make a zone-only follow-up put the held object down ("then onto the shelf").
ONTO = [("onto",), ("into",)]
PRONOUNS = {"it", "them", "one"}
# Phrases that make a clause the last thing to do.
END_MARKERS = [
    ("finish",),
    ("finishes",),
    ("end",),
    ("ends",),
    ("eventually",),
    ("final",),
    ("in", "the", "end"),
    ("at", "the", "end"),
    ("last",),
    ("lastly",),
    ("finally",),
]
# Phrases that make a clause the first thing to do (see clauses.says_first).
FIRST_MARKERS = [
    ("first",),
    ("start", "by"),
    ("begin", "by"),
    ("start", "at"),
    ("begin", "at"),
    ("starting", "at"),
    ("beginning", "at"),
    ("to", "begin"),
]
# Phrases naming the delivery to do first: "start with the cup", "the cup first".
ORDER_MARKERS = [
    ("first",),
    ("start", "with"),
    ("begin", "with"),
    ("starting", "with"),
    ("beginning", "with"),
    ("start", "by"),
    ("begin", "by"),
    ("dealing", "with"),
]
# Multi-word ways of saying swap.
SWAP_PHRASES = [
    ("change", "places"),
    ("trade", "places"),
    ("switch", "places"),
    ("changed", "places"),
    ("traded", "places"),
    ("switched", "places"),
    ("swapped", "places"),
    ("exchanged", "places"),
    ("trade", "positions"),
    ("swap", "places"),
    ("exchange", "places"),
    ("vice", "versa"),
    ("trade", "spots"),
    ("swap", "spots"),
    ("switch", "spots"),
]
# Verbs that explicitly put an object down (a later "without letting go" does not undo them).
PUT = {"put", "place", "set", "leave", "drop", "deposit", "placing", "setting", "leaving", "dropping", "putting"}
# Verbs of replacing: "replace the plate with the cup", "the plate is replaced by the cup".
REPLACE = {"replace", "replaced", "replacing"}
# Places that are "where the object mentioned before is": "leave the cup in the same place".
SAME_PLACE = [("the", "same", "place"), ("the", "same", "spot")]
# Prepositions that make each following place a destination of its own ("to the table and
# back to the shelf": put it down at both).
DESTINATION = {"to", "onto", "into"}
