"""Object library files: objects as data (TOML or JSON), checked, merged with the 29 built-ins.

Takes a file path (``.toml`` or ``.json``) and the scene/action settings the checks need; gives
``ObjectSpec``s, an ``objects.ObjectSet`` (the built-ins plus the file's objects, narrowed to a
selection) and its record for a dataset's sidecar. Plain Python (``tomllib``, ``json``): the
command line checks a library before JAX is imported. Field by field: docs/objects.md.

A file holds ``[[object]]`` tables (JSON: ``{"object": [...]}``), each::

    name, groups, mass, friction, colour, parts.<slot> = {size, centre}  or  sphere_radius,
    inner (optional: a container's inner half-extents x, y and rim height)

Every refusal is one ``UserError`` line naming the file, the object and the field.
"""
from __future__ import annotations

import hashlib
import json
import math
import tomllib
from pathlib import Path
from typing import Any, Iterable, Mapping

from relaff_jax.errors import UserError

from . import objects as lib

OBJECT_KEYS = ("name", "groups", "mass", "friction", "colour", "parts", "sphere_radius", "inner")
PART_KEYS = ("size", "centre")
# The finger joint's range (scenes/arm.xml, slide range 0..0.21 m per finger): a top-down grasp
# opens each finger to half the toy's narrower side plus ``ActionConfig.grip_margin``.
FINGER_RANGE = 0.21
# Least RGB distance between two objects' colours. The simulated camera segments by geom, so
# colours only tell objects apart in pictures and for a real colour segmenter; the built-in
# palette's closest pair is 0.187 apart, and a new colour must keep at least this distance.
COLOUR_TOLERANCE = 0.15


def _refuse(where: str, msg: str) -> None:
    raise UserError(f"{where}: {msg}")


def _number(where: str, field: str, v: Any, positive: bool = True) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        _refuse(where, f"{field} must be a finite number{' > 0' if positive else ''}, got {v!r}")
    return float(v)


def _vector(where: str, field: str, v: Any, n: int = 3, positive: bool = True) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        _refuse(where, f"{field} must be a list of {n} numbers, got {v!r}")
    return tuple(_number(where, f"{field}[{i}]", x, positive) for i, x in enumerate(v))


def _kind(groups: tuple[str, ...], sphere: float, inner: Any) -> str:
    """The built-ins' kinds follow from the data: a user object gets its kind the same way."""
    if sphere:
        return "ball"
    if "rake" in groups:
        return "rake"
    if inner is not None:
        return "container"
    return {"toy": "block", "base": "flat", "obstacle": "obstacle"}[groups[0]]


def parse_spec(d: Any, where: str, colour_of: Mapping[str, tuple] = {}) -> lib.ObjectSpec:
    """One object table -> ``ObjectSpec``; the template's and the sizes' own checks (not those
    needing the scene settings: ``check_fits``). ``where`` prefixes every error."""
    if not isinstance(d, Mapping):
        _refuse(where, f"an object must be a table, got {d!r}")
    name = d.get("name")
    if not isinstance(name, str) or not name.isidentifier():
        _refuse(where, f"name must be a word of letters, digits and _ (not starting with a digit), got {name!r}")
    where = f"{where}: object {name!r}"
    unknown = sorted(set(d) - set(OBJECT_KEYS))
    if unknown:
        _refuse(where, f"unknown key {unknown[0]!r}; valid keys: {', '.join(OBJECT_KEYS)}")
    for key in ("groups", "mass", "friction", "colour"):
        if key not in d:
            _refuse(where, f"{key} is missing")
    groups = d["groups"]
    if not isinstance(groups, (list, tuple)) or not groups or len(set(groups)) != len(groups):
        _refuse(where, f"groups must be a non-empty list of distinct groups, got {groups!r}")
    for g in groups:
        if g not in lib.GROUPS:
            _refuse(where, f"groups: unknown group {g!r}; valid groups: {', '.join(lib.GROUPS)}")
    groups = tuple(groups)
    others = [g for g in groups if g != "toy"]
    if len(others) > 1 or ("toy" in groups and others and others != ["base"]):
        _refuse(where, f"groups {list(groups)}: at most one of base, obstacle, rake, and a toy may only also "
                       "be a base (as the cup is)")
    mass = _number(where, "mass", d["mass"])
    friction = _number(where, "friction", d["friction"])
    colour = _vector(where, "colour", d["colour"], positive=False)
    if not all(0.0 <= c <= 1.0 for c in colour):
        _refuse(where, f"colour must be RGB in [0, 1], got {list(colour)}")
    for other, c in colour_of.items():
        dist = math.dist(colour, c)
        if dist < COLOUR_TOLERANCE:
            _refuse(where, f"colour {list(colour)} is {dist:.3f} from the colour of {other!r} {list(c)}: keep "
                           f"at least {COLOUR_TOLERANCE} (RGB distance) so that colour tells the objects apart")
    sphere = _number(where, "sphere_radius", d["sphere_radius"]) if "sphere_radius" in d else 0.0
    parts = d.get("parts", {})
    if not isinstance(parts, Mapping):
        _refuse(where, f"parts must be a table of slot name -> {{size, centre}}, got {parts!r}")
    toy_only = groups == ("toy",)
    slots = ("box",) if toy_only else lib.OTHER_GEOMS
    if sphere and not toy_only:
        _refuse(where, "sphere_radius: only a toy can be a ball (the other object's slot holds boxes)")
    if sphere and parts:
        _refuse(where, "a ball (sphere_radius) has no parts")
    if not sphere and not parts:
        _refuse(where, "parts is missing (or give a toy a sphere_radius)")
    boxes = []
    for slot, p in parts.items():
        if slot not in slots:
            what = "the toy slot's box" if toy_only else "the other slot's boxes"
            _refuse(where, f"parts.{slot}: not a slot of the template ({what}: {', '.join(slots)})")
        pw = f"parts.{slot}"
        if not isinstance(p, Mapping):
            _refuse(where, f"{pw} must be a table with size and centre, got {p!r}")
        bad = sorted(set(p) - set(PART_KEYS))
        if bad:
            _refuse(where, f"{pw}: unknown key {bad[0]!r}; valid keys: size, centre")
        if "size" not in p:
            _refuse(where, f"{pw}.size is missing")
        size = _vector(where, f"{pw}.size", p["size"])
        centre = _vector(where, f"{pw}.centre", p.get("centre", (0.0, 0.0, size[2] / 2)), positive=False)
        if centre[2] - size[2] / 2 < -1e-9:
            _refuse(where, f"{pw}: reaches below the table (z = 0 is the object's bottom)")
        boxes.append((slot, lib.Box(size, centre)))
    boxes.sort(key=lambda sb: slots.index(sb[0]))  # template order, whatever the file's
    if not toy_only and not sphere and "base" not in parts:
        _refuse(where, "parts.base is missing (the other slot's main box)")
    if "rake" in groups and "wall_xp" not in parts:
        _refuse(where, "parts.wall_xp is missing (a rake's head; base is its handle)")
    inner = None
    if "inner" in d:
        if "base" not in groups:
            _refuse(where, "inner: only a base can be a container")
        inner = _vector(where, "inner", d["inner"])
        plate = dict(boxes)["base"]
        if inner[0] >= plate.size[0] / 2 or inner[1] >= plate.size[1] / 2:
            _refuse(where, f"inner {list(inner)}: the inner half-extents must be smaller than the base's "
                           f"({plate.size[0] / 2:g}, {plate.size[1] / 2:g})")
    spec = lib.ObjectSpec(name, groups, colour, mass, friction, tuple(boxes), sphere, inner,
                          _kind(groups, sphere, inner))
    if inner is not None and inner[2] > spec.height + 1e-9:
        _refuse(where, f"inner: rim height {inner[2]:g} is above the object's top {spec.height:g}")
    return spec


def check_fits(spec: lib.ObjectSpec, where: str, scene: Any, grip_margin: float) -> None:
    """Sizes the gripper and the sampled table region allow (``scene``: a ``SceneConfig``)."""
    where = f"{where}: object {spec.name!r}"
    if "toy" in spec.groups:
        narrow = min(spec.extent[:2])
        if narrow / 2 + grip_margin > FINGER_RANGE:
            _refuse(where, f"a toy {100 * narrow:.1f} cm across its narrower side is more than the gripper can "
                           f"hold: each finger opens at most {FINGER_RANGE} m, to half the side plus "
                           f"action.grip_margin = {grip_margin} (at most {200 * (FINGER_RANGE - grip_margin):.0f} cm)")
    if "rake" not in spec.groups:
        r, lo, hi = spec.footprint_radius, scene.min_radius, scene.workspace_radius
        if lo + r > hi - r:
            _refuse(where, f"footprint radius {r:.3f} m does not fit the table region scenes sample (between "
                           f"action.scene.min_radius = {lo} and workspace_radius = {hi} m of the robot, "
                           f"shrunk by the radius on both sides)")


def read_file(path: str | Path) -> list[Any]:
    """The raw object tables of a ``.toml`` or ``.json`` library file."""
    p = Path(path)
    where = f"object library {path}"
    if p.suffix.lower() not in (".toml", ".json"):
        _refuse(where, "must be a .toml or .json file")
    try:
        text = p.read_text()
    except OSError as e:
        _refuse(where, f"cannot be read ({e.strerror or e})")
    try:
        doc = tomllib.loads(text) if p.suffix.lower() == ".toml" else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as e:
        _refuse(where, f"is not valid {p.suffix[1:].upper()} ({e})")
    if not isinstance(doc, dict) or set(doc) - {"object"}:
        bad = sorted(set(doc) - {"object"}) if isinstance(doc, dict) else [type(doc).__name__]
        _refuse(where, f"unknown top-level key {bad[0]!r}: a library holds only [[object]] tables")
    objs = doc.get("object", [])
    if not isinstance(objs, list) or not objs:
        _refuse(where, "holds no [[object]] tables")
    return objs


def load_library(path: str | Path, scene: Any = None, grip_margin: float = 0.02) -> tuple[lib.ObjectSpec, ...]:
    """The checked objects of a library file (every refusal a ``UserError`` naming the object and
    field). A name of a built-in is refused: a library adds objects, it never redefines one."""
    where = f"object library {path}"
    colours = {s.name: s.colour for s in lib.OBJECTS.values()}
    out = []
    for i, d in enumerate(read_file(path)):
        name = d.get("name") if isinstance(d, Mapping) else None
        if name in lib.OBJECTS:
            _refuse(where, f"object {name!r}: name clashes with a built-in object; choose another name "
                           "(a library adds objects, it does not replace built-ins)")
        if name in colours:
            _refuse(where, f"object {name!r}: defined twice in the file")
        spec = parse_spec(d, f"{where} (object {i + 1})" if not isinstance(name, str) else where, colours)
        if scene is None:  # here, not at the top: the config tree imports this module
            from relaff_jax.config.action import SceneConfig
            scene = SceneConfig()
        check_fits(spec, where, scene, grip_margin)
        colours[spec.name] = spec.colour
        out.append(spec)
    return tuple(out)


def select(user: tuple[lib.ObjectSpec, ...], names: Iterable[str], library: str = "") -> lib.ObjectSet:
    """The built-ins plus ``user``, in that order, narrowed to ``names`` (empty: all of them)."""
    merged = {**lib.OBJECTS, **{s.name: s for s in user}}
    names = tuple(names)
    for n in names:
        if n not in merged:
            raise UserError(f"config key 'action.scene.objects': unknown object {n!r}; valid objects: {', '.join(merged)}")
    keep = set(names) or set(merged)
    specs = tuple(s for s in merged.values() if s.name in keep)
    if not any("toy" in s.groups for s in specs):
        raise UserError("config key 'action.scene.objects': selects no toy; every scene needs one")
    out = lib.ObjectSet(specs, library, names)
    if not out.pairs():
        raise UserError("config key 'action.scene.objects': selects no object to pair with a toy (a base, obstacle or rake)")
    return out


def scene_objects(scene: Any, grip_margin: float = 0.02) -> lib.ObjectSet:
    """The object set a ``SceneConfig`` selects (``objects``, ``library``): the built-ins when
    both are left at their defaults."""
    if not scene.library and not scene.objects:
        return lib.BUILTIN_SET
    user = load_library(scene.library, scene, grip_margin) if scene.library else ()
    return select(user, scene.objects, scene.library)


def use_scene(scene: Any, grip_margin: float = 0.02) -> lib.ObjectSet:
    """Activate the set ``scene`` selects (``objects.activate``) unless the active set already is
    the one it names (e.g. activated from a dataset's record); returns the active set."""
    cur = lib.active()
    if (cur.library, cur.selection) != (scene.library, tuple(scene.objects)):
        lib.activate(scene_objects(scene, grip_margin))
    return lib.active()


# --- records: the specs in a file's form, a dataset's sidecar entry ---------------------------

def spec_dict(s: lib.ObjectSpec) -> dict:
    """``s`` as a library file's table (what ``parse_spec`` reads back into an equal spec)."""
    d: dict[str, Any] = {"name": s.name, "groups": list(s.groups), "mass": s.mass, "friction": s.friction,
                         "colour": list(s.colour)}
    if s.sphere_radius:
        d["sphere_radius"] = s.sphere_radius
    if s.parts:
        d["parts"] = {k: {"size": list(b.size), "centre": list(b.centre)} for k, b in s.parts}
    if s.inner is not None:
        d["inner"] = list(s.inner)
    return d


def digest(specs: Iterable[lib.ObjectSpec]) -> str:
    """sha256 of the specs' canonical JSON (their file form, in order)."""
    text = json.dumps([spec_dict(s) for s in specs], sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def record(objs: lib.ObjectSet) -> dict:
    """A sidecar's ``objects`` entry: the selected names, the library's own objects as specs, and
    ``digest`` of every selected spec (built-ins included)."""
    return {"sha256": digest(objs.specs), "library": objs.library, "selection": list(objs.selection),
            "names": [s.name for s in objs.specs],
            "specs": [spec_dict(s) for s in objs.specs if s.name not in lib.OBJECTS]}


def from_record(rec: Mapping[str, Any] | None) -> lib.ObjectSet:
    """The set a sidecar records (``record``); None (a dataset made before libraries): the built-ins."""
    if not rec:
        return lib.BUILTIN_SET
    user = {d["name"]: parse_spec(d, "dataset record") for d in rec["specs"]}
    specs = tuple(user[n] if n in user else lib.OBJECTS[n] for n in rec["names"])
    if digest(specs) != rec["sha256"]:
        raise UserError(f"the dataset's object record does not match its sha256 {rec['sha256'][:12]}: "
                        "the built-in objects changed since it was written")
    return lib.ObjectSet(specs, rec.get("library", ""), tuple(rec.get("selection", ())))


def use_recorded(meta: Mapping[str, Any]) -> lib.ObjectSet:
    """Activate the object set a dataset sidecar records; returns it."""
    rec = (meta.get("config") or {}).get("objects") if isinstance(meta.get("config"), Mapping) else None
    objs = from_record(rec)
    lib.activate(objs)
    return objs


def to_toml(specs: Iterable[lib.ObjectSpec]) -> str:
    """A library file holding ``specs`` (floats written by ``repr``: they read back exactly)."""
    val = lambda v: json.dumps(v) if isinstance(v, str) else ("[" + ", ".join(val(x) for x in v) + "]"
                                                               if isinstance(v, list) else repr(float(v)))
    lines = []
    for s in specs:
        d = spec_dict(s)
        parts = d.pop("parts", {})
        lines.append("[[object]]")
        lines += [f"{k} = {val(v)}" for k, v in d.items()]
        for k, p in parts.items():
            lines.append(f"parts.{k} = {{ size = {val(p['size'])}, centre = {val(p['centre'])} }}")
        lines.append("")
    return "\n".join(lines)
