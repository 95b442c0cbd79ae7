"""The plan grammar and a symbolic check of a plan against a scene.

A step is exactly `move to the <colour> zone`, `pick the <object>` or `place the <object>`
(docs/participant/planning.md; `core/src/plan.rs`), with the scene's zone colours and object names.
`check` also acts the plan out: a pick needs the robot at the object's zone with an empty
gripper, a place needs something held (it lands in the zone the robot is at). The server scores
any well-formed plan; this check is what keeps a language model's answer sensible.
"""


def valid_steps(scene):
    """Every step the grammar allows in this scene (the vocabulary of constrained decoding)."""
    out = ["move to the %s zone" % z for z in scene.zones]
    for o in scene.objects:
        out += ["pick the %s" % o, "place the %s" % o]
    return out


def check(plan, scene, max_steps=64):
    """None if the plan is well formed and executes in the scene, else what is wrong."""
    if not isinstance(plan, list) or not plan:
        return "the plan must be a non-empty list of steps"
    if len(plan) > max_steps:
        return "the plan has %d steps; at most %d" % (len(plan), max_steps)
    allowed = set(valid_steps(scene))
    loc = dict(scene.objects)
    robot = held = None
    for i, step in enumerate(plan, 1):
        if not isinstance(step, str) or step not in allowed:
            return "step %d %r is not one of the allowed steps" % (i, step)
        if step.startswith("move to the "):
            robot = step[len("move to the ") : -len(" zone")]
        elif step.startswith("pick the "):
            obj = step[len("pick the ") :]
            if held is not None:
                return "step %d picks the %s while holding the %s" % (i, obj, held)
            if loc.get(obj) != robot:
                return "step %d picks the %s, which is not in the zone the robot is at" % (i, obj)
            held, loc[obj] = obj, None
        else:
            obj = step[len("place the ") :]
            if held != obj:
                return "step %d places the %s, which the robot does not hold" % (i, obj)
            if robot is None:
                return "step %d places the %s before moving to any zone" % (i, obj)
            loc[obj], held = robot, None
    return None
