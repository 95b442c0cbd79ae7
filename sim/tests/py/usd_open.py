"""Open exported .usda files with Pixar's USD (`pip install usd-core`) and print, as JSON, what
the Rust test compares: prim counts by type, the world translation of every furniture, zone and
object Xform, and the world-space extent of every Cube (so a Cube's size 2 and its scale are
checked as USD itself reads them). Usage: usd_open.py FILE.usda..."""

import json
import sys

from pxr import Usd, UsdGeom


def describe(path):
    stage = Usd.Stage.Open(path)
    if stage is None:
        raise SystemExit(f"{path}: USD could not open it")
    counts = {}
    translations = {}
    cubes = {}
    cache = UsdGeom.XformCache()
    for prim in stage.Traverse():
        kind = prim.GetTypeName()
        counts[kind] = counts.get(kind, 0) + 1
        parent = prim.GetParent().GetName()
        if kind == "Xform" and parent in ("Furniture", "Zones", "Objects"):
            t = cache.GetLocalToWorldTransform(prim).ExtractTranslation()
            translations[str(prim.GetPath())] = [t[0], t[1], t[2]]
        if kind == "Cube":
            world = cache.GetLocalToWorldTransform(prim)
            size = UsdGeom.Cube(prim).GetSizeAttr().Get()
            # The cube's three edge vectors in world space: lengths are the box's full sizes.
            edges = [world.TransformDir(v) for v in ((size, 0, 0), (0, size, 0), (0, 0, size))]
            cubes[str(prim.GetPath())] = [e.GetLength() for e in edges]
    return {
        "up_axis": UsdGeom.GetStageUpAxis(stage),
        "meters_per_unit": UsdGeom.GetStageMetersPerUnit(stage),
        "default_prim": stage.GetDefaultPrim().GetName(),
        "counts": counts,
        "translations": translations,
        "cubes": cubes,
    }


print(json.dumps({p: describe(p) for p in sys.argv[1:]}))
