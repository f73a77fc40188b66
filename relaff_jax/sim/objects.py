"""The 29-object library of the paper (section IV-C): 5 toys, 15 bases, 5 obstacles, 5 rakes.

Takes nothing; gives a registry ``name -> ObjectSpec`` (group(s), colour, mass, friction and
its collision geometry). The cup is both a toy and a base, so there are 29 distinct
objects but 30 group memberships.

Every object is built from the same small *geometry template*, so that one MJX model
structure serves every object pair (the per-pair differences are sizes, positions, masses
and colours, carried as batched model fields, see ``world.py``):

* the toy slot has 2 geoms: ``sphere`` and ``box``;
* the other slot has 5 boxes: ``base`` and four ``walls``.

A slot geom that an object does not use is *collapsed*: a 1 mm geom hidden at the centre
of the object's main geom, where it can never touch anything. Containers (cup, bowl, box,
basket, bucket, pan) are a bottom plate plus four walls a toy can sit inside; flat supports
are one plate; obstacles one box; rakes a handle plus a head. Round containers are
approximated by square walls (the camera segments by colour and the physics only needs
walls, so this changes the look, not the affordances). As a toy the cup is a closed,
cup-sized block: nothing is ever put into the toy.

All sizes are full extents in metres, masses in kg, in the object's own frame
(x forward, z up, origin at the centre of the footprint on the table, z = 0 at the bottom).

A run's objects are an ``ObjectSet``: the built-ins (``BUILTIN_SET``) unless a library file
adds objects or the config selects some (``object_library``, docs/objects.md). ``get``,
``members`` and ``pairs`` read the *active* set (``activate``), which the config check or a
dataset's record sets before any world is built.
"""
from __future__ import annotations

import dataclasses
import functools

GROUPS = ("toy", "base", "obstacle", "rake")

# Slot templates: geom names in model order (see world.py).
TOY_GEOMS = ("sphere", "box")
OTHER_GEOMS = ("base", "wall_xp", "wall_xn", "wall_yp", "wall_yn")

COLLAPSED = 0.001  # half-size (m) of a geom an object does not use


@dataclasses.dataclass(frozen=True)
class Box:
    """A box part: full ``size`` (x, y, z) and ``centre`` in the object frame."""

    size: tuple[float, float, float]
    centre: tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class ObjectSpec:
    """One object of the library.

    ``parts`` maps slot-geom names to boxes; a ``sphere_radius`` > 0 makes a ball.
    ``inner`` is the container's inner footprint half-extents (x, y) and rim height (m),
    or None for objects a toy cannot be inside.
    """

    name: str
    groups: tuple[str, ...]
    colour: tuple[float, float, float]
    mass: float
    friction: float
    parts: tuple[tuple[str, Box], ...] = ()
    sphere_radius: float = 0.0
    inner: tuple[float, float, float] | None = None
    kind: str = ""  # container, flat, block, ball, obstacle, rake

    @property
    def group(self) -> str:
        """Primary group (the cup's is ``toy``)."""
        return self.groups[0]

    @property
    def height(self) -> float:
        if self.sphere_radius:
            return 2 * self.sphere_radius
        return max(b.centre[2] + b.size[2] / 2 for _, b in self.parts)

    @property
    def footprint_radius(self) -> float:
        """Radius of the smallest vertical cylinder about the origin enclosing the object."""
        if self.sphere_radius:
            return self.sphere_radius
        r = 0.0
        for _, b in self.parts:
            for sx in (-1, 1):
                for sy in (-1, 1):
                    x = b.centre[0] + sx * b.size[0] / 2
                    y = b.centre[1] + sy * b.size[1] / 2
                    r = max(r, (x * x + y * y) ** 0.5)
        return r

    @property
    def top_extent(self) -> tuple[float, float]:
        """Half-extents (x, y) of the object's top surface footprint (for placing a toy on it)."""
        b = dict(self.parts).get("base") or dict(self.parts).get("box")
        return (b.size[0] / 2, b.size[1] / 2)

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "group": self.group,
            "groups": list(self.groups),
            "kind": self.kind,
            "colour": [round(c, 3) for c in self.colour],
            "mass_kg": self.mass,
            "size_cm": [round(100 * s, 1) for s in self.extent],
            "container": self.inner is not None,
        }

    @property
    def extent(self) -> tuple[float, float, float]:
        """Full bounding-box size (x, y, z) in metres."""
        if self.sphere_radius:
            return (2 * self.sphere_radius,) * 3
        lo = [min(b.centre[i] - b.size[i] / 2 for _, b in self.parts) for i in range(3)]
        hi = [max(b.centre[i] + b.size[i] / 2 for _, b in self.parts) for i in range(3)]
        return tuple(h - l for h, l in zip(hi, lo))  # type: ignore[return-value]


# 29 well-separated colours (RGB in 0..1): the camera segments objects by colour.
PALETTE = (
    (0.90, 0.10, 0.10), (0.10, 0.60, 0.10), (0.10, 0.20, 0.90), (0.95, 0.85, 0.10),
    (0.60, 0.10, 0.70), (0.10, 0.80, 0.80), (0.95, 0.50, 0.05), (0.55, 0.30, 0.10),
    (0.95, 0.45, 0.70), (0.45, 0.80, 0.20), (0.30, 0.30, 0.55), (0.80, 0.80, 0.55),
    (0.50, 0.00, 0.15), (0.00, 0.40, 0.40), (0.70, 0.60, 0.95), (0.40, 0.40, 0.00),
    (0.00, 0.00, 0.45), (1.00, 0.75, 0.55), (0.25, 0.55, 0.95), (0.60, 0.95, 0.60),
    (0.85, 0.25, 0.45), (0.35, 0.15, 0.35), (0.95, 0.95, 0.80), (0.15, 0.35, 0.15),
    (0.75, 0.40, 0.30), (0.45, 0.65, 0.65), (0.90, 0.65, 0.15), (0.25, 0.75, 0.50),
    (0.65, 0.25, 0.95),
)


def _block(sx: float, sy: float, sz: float, part: str = "base") -> tuple[tuple[str, Box], ...]:
    return ((part, Box((sx, sy, sz), (0.0, 0.0, sz / 2))),)


def _container(sx: float, sy: float, sz: float, wall: float, bottom: float = 0.01):
    """Bottom plate plus four walls; returns (parts, inner half-extents + rim height)."""
    parts = (
        ("base", Box((sx, sy, bottom), (0.0, 0.0, bottom / 2))),
        ("wall_xp", Box((wall, sy, sz), (sx / 2 - wall / 2, 0.0, sz / 2))),
        ("wall_xn", Box((wall, sy, sz), (-sx / 2 + wall / 2, 0.0, sz / 2))),
        ("wall_yp", Box((sx - 2 * wall, wall, sz), (0.0, sy / 2 - wall / 2, sz / 2))),
        ("wall_yn", Box((sx - 2 * wall, wall, sz), (0.0, -sy / 2 + wall / 2, sz / 2))),
    )
    return parts, (sx / 2 - wall, sy / 2 - wall, sz)


def _rake(handle: float, head_w: float, head_d: float, head_h: float, offset: float = 0.0):
    """Handle along +x from the grip (origin) and a head across it at the far end.

    The object origin is the grip point at the handle's near end; ``offset`` shifts the head
    sideways (an L-hook has its head on one side only).
    """
    t = 0.025  # handle cross-section
    return (
        ("base", Box((handle, t, t), (handle / 2, 0.0, t / 2))),
        ("wall_xp", Box((head_d, head_w, head_h), (handle - head_d / 2, offset, head_h / 2))),
    )


def _build() -> dict[str, ObjectSpec]:
    specs: list[ObjectSpec] = []

    def add(name, groups, mass, friction, kind, parts=(), radius=0.0, inner=None):
        colour = PALETTE[len(specs)]
        specs.append(ObjectSpec(name, tuple(groups), colour, mass, friction, tuple(parts),
                                radius, inner, kind))

    # Toys (5). The cup is a toy (closed block) and a base (open container, below).
    add("ball", ["toy"], 0.06, 0.9, "ball", radius=0.035)
    add("block", ["toy"], 0.08, 0.9, "block", _block(0.05, 0.05, 0.05, "box"))
    add("toy_car", ["toy"], 0.15, 0.9, "block", _block(0.10, 0.05, 0.04, "box"))
    add("toy_can", ["toy"], 0.20, 0.9, "block", _block(0.065, 0.065, 0.12, "box"))
    cup_parts, cup_inner = _container(0.09, 0.09, 0.10, 0.006, 0.008)
    add("cup", ["toy", "base"], 0.25, 0.9, "container", cup_parts, inner=cup_inner)

    # Bases (15 including the cup): 6 containers, 9 flat supports.
    for name, (sx, sy, sz, w), mass in (
        ("bowl", (0.17, 0.17, 0.07, 0.008), 0.35),
        ("open_box", (0.26, 0.20, 0.12, 0.008), 0.40),
        ("basket", (0.32, 0.24, 0.15, 0.010), 0.50),
        ("bucket", (0.23, 0.23, 0.20, 0.010), 0.60),
        ("baking_pan", (0.30, 0.22, 0.06, 0.008), 0.45),
    ):
        parts, inner = _container(sx, sy, sz, w)
        add(name, ["base"], mass, 1.0, "container", parts, inner=inner)
    for name, (sx, sy, sz), mass in (
        ("tray", (0.40, 0.30, 0.02), 0.50),
        ("plate", (0.25, 0.25, 0.015), 0.40),
        ("cutting_board", (0.36, 0.22, 0.02), 0.60),
        ("book", (0.24, 0.17, 0.03), 0.50),
        ("baking_sheet", (0.40, 0.30, 0.01), 0.45),
        ("placemat", (0.40, 0.30, 0.006), 0.10),
        ("magazine", (0.28, 0.21, 0.008), 0.20),
        ("pallet_board", (0.45, 0.35, 0.04), 0.90),
        ("lid", (0.20, 0.20, 0.015), 0.25),
    ):
        add(name, ["base"], mass, 1.0, "flat", _block(sx, sy, sz))

    # Obstacles (5): things that block the arm's way to a toy.
    for name, (sx, sy, sz), mass in (
        ("brick", (0.20, 0.10, 0.06), 1.0),
        ("cereal_box", (0.07, 0.19, 0.28), 0.45),
        ("bottle", (0.08, 0.08, 0.25), 0.70),
        ("wall_panel", (0.04, 0.40, 0.25), 0.90),
        ("vase", (0.12, 0.12, 0.30), 0.80),
    ):
        add(name, ["obstacle"], mass, 0.8, "obstacle", _block(sx, sy, sz))

    # Rakes (5): a handle held in the gripper and a head.
    for name, geom, mass in (
        ("rake_short", (0.40, 0.20, 0.03, 0.03, 0.0), 0.25),
        ("rake_long", (0.60, 0.25, 0.03, 0.03, 0.0), 0.35),
        ("hoe", (0.50, 0.12, 0.03, 0.06, 0.0), 0.35),
        ("t_stick", (0.45, 0.30, 0.02, 0.02, 0.0), 0.25),
        ("l_hook", (0.50, 0.12, 0.02, 0.03, 0.06), 0.30),
    ):
        add(name, ["rake"], mass, 1.0, "rake", _rake(*geom))

    return {s.name: s for s in specs}


OBJECTS: dict[str, ObjectSpec] = _build()  # the built-ins (``object_library`` adds a file's)
OBJECT_NAMES: tuple[str, ...] = tuple(OBJECTS)

from relaff_jax.constants import PAIRINGS  # noqa: E402,F401 (re-exported)


@dataclasses.dataclass(frozen=True)
class ObjectSet:
    """The objects a run uses: ``specs`` in registry order (the built-ins first, then a library
    file's), the ``library`` path they came from ("" none) and the ``selection`` as the config
    gave it (empty: every object). Hashable: ``world.build_world`` is cached per set."""

    specs: tuple[ObjectSpec, ...]
    library: str = ""
    selection: tuple[str, ...] = ()

    @functools.cached_property
    def by_name(self) -> dict[str, ObjectSpec]:
        return {s.name: s for s in self.specs}

    def get(self, name: str) -> ObjectSpec:
        """Look up an object by name; an unknown name lists the valid ones."""
        try:
            return self.by_name[name]
        except KeyError:
            raise KeyError(f"unknown object {name!r}; valid objects: {', '.join(self.by_name)}") from None

    def members(self, group: str) -> tuple[str, ...]:
        """Names of the objects in ``group`` (toy, base, obstacle, rake)."""
        if group not in GROUPS:
            raise KeyError(f"unknown group {group!r}; valid groups: {', '.join(GROUPS)}")
        return tuple(s.name for s in self.specs if group in s.groups)

    def pairs(self) -> tuple[tuple[str, str, str], ...]:
        """All (toy, other, pairing) scene pairs: one toy plus one object of another group.

        An object that is a toy and a base (the cup) is never paired with itself: the
        built-ins give 5*15 - 1 + 25 + 25 = 124 pairs.
        """
        out = []
        for group in ("base", "obstacle", "rake"):
            for toy in self.members("toy"):
                for other in self.members(group):
                    if toy != other:
                        out.append((toy, other, f"toy+{group}"))
        return tuple(out)


BUILTIN_SET = ObjectSet(tuple(OBJECTS.values()))
# The set every lookup below reads: the built-ins unless a run activates another
# (``object_library.use_scene`` from the config, ``use_recorded`` from a dataset's sidecar).
_ACTIVE = [BUILTIN_SET]


def active() -> ObjectSet:
    return _ACTIVE[0]


def activate(objs: ObjectSet) -> ObjectSet:
    """Make ``objs`` the active set; returns the one it replaces."""
    prev, _ACTIVE[0] = _ACTIVE[0], objs
    return prev


def get(name: str) -> ObjectSpec:
    """Look up an object of the active set by name; an unknown name lists the valid ones."""
    return active().get(name)


def members(group: str) -> tuple[str, ...]:
    """Names of the active set's objects in ``group`` (toy, base, obstacle, rake)."""
    return active().members(group)


def pairs() -> tuple[tuple[str, str, str], ...]:
    """All (toy, other, pairing) scene pairs of the active set (``ObjectSet.pairs``)."""
    return active().pairs()
