"""Where the objects of a settled scene are, as the motor programs see them.

Takes an action world's pairs (``world.World``) and one scene's settled ``qpos`` (14,)
(toy's free joint, then the other object's); gives per-pair bounding boxes (``Geometry``,
numpy, built once), world-frame ``Body`` views of the toy and the other object, top-down
grasps of a body (``top_down_grasp``) and small helpers for horizontal directions and IK
targets. Single scene, pure JAX; the caller vmaps and jits.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import arm as A
from . import objects as lib
from . import world as wd
from .geometry import quat_to_mat
from .templates import ActionConfig, is_v4


@dataclasses.dataclass(frozen=True, eq=False)
class Geometry:
    """Per-pair object geometry in each object's own frame (origin at the footprint's bottom
    centre; rakes: the grip point). (P, 3) bounding boxes ``toy_lo``/``toy_hi`` and
    ``oth_lo``/``oth_hi``; rake head: ``head_x0`` near face x, ``head_y`` (P, 2) y range;
    ``toy_mass``/``oth_mass`` (P,) kg; ``oth_inner`` (P, 3) a container's inner half extents
    (x, y) and floor height (its bottom plate's top), zeros for the others; ``toy_radius`` (P,)
    the ball's radius (its half width in every direction), 0 for the other toys."""

    pairing: np.ndarray
    toy_lo: np.ndarray
    toy_hi: np.ndarray
    oth_lo: np.ndarray
    oth_hi: np.ndarray
    head_x0: np.ndarray
    head_y: np.ndarray
    toy_mass: np.ndarray
    oth_mass: np.ndarray
    oth_inner: np.ndarray
    toy_radius: np.ndarray


def _bbox(spec: lib.ObjectSpec) -> tuple[np.ndarray, np.ndarray]:
    if spec.sphere_radius:
        r = spec.sphere_radius
        return np.array([-r, -r, 0.0]), np.array([r, r, 2 * r])
    lo = np.min([np.subtract(b.centre, np.divide(b.size, 2)) for _, b in spec.parts], axis=0)
    hi = np.max([np.add(b.centre, np.divide(b.size, 2)) for _, b in spec.parts], axis=0)
    return lo, hi


@functools.lru_cache(maxsize=4)
def geometry(world: wd.World) -> Geometry:
    rows = []
    for toy, other, pairing in world.pairs:
        t, o = lib.get(toy), lib.get(other)
        (tl, th), (ol, oh) = _bbox(t), _bbox(o)
        head_x0, head_y = 0.0, (0.0, 0.0)
        if o.kind == "rake":
            head = dict(o.parts)["wall_xp"]
            head_x0 = head.centre[0] - head.size[0] / 2
            head_y = (head.centre[1] - head.size[1] / 2, head.centre[1] + head.size[1] / 2)
        inner = (0.0, 0.0, 0.0)
        if o.inner is not None:
            plate = dict(o.parts)["base"]
            inner = (o.inner[0], o.inner[1], plate.centre[2] + plate.size[2] / 2)
        rows.append((lib.PAIRINGS.index(pairing), tl, th, ol, oh, head_x0, head_y, t.mass, o.mass, inner,
                     t.sphere_radius))
    cols = list(zip(*rows))
    return Geometry(np.asarray(cols[0], np.int32), *(np.asarray(c, np.float32) for c in cols[1:]))


class Body(NamedTuple):
    """World-frame view of one object: origin ``pos``, ``mat``, box ``lo``/``hi`` (own frame)."""

    pos: jax.Array
    mat: jax.Array
    lo: jax.Array
    hi: jax.Array

    @property
    def centre(self) -> jax.Array:
        return self.pos + self.mat @ ((self.lo + self.hi) / 2)

    def z_range(self) -> tuple[jax.Array, jax.Array]:
        signs = jnp.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], jnp.float32)
        corners = self.lo + signs * (self.hi - self.lo)
        z = self.pos[2] + corners @ self.mat[2]
        return z.min(), z.max()

    def half_width(self, direction: jax.Array) -> jax.Array:
        """Half extent of the box along a world direction (3,) (its support)."""
        return jnp.sum(jnp.abs(self.mat.T @ direction) * (self.hi - self.lo) / 2)


def bodies(geo: Geometry, pair: jax.Array, qpos: jax.Array) -> tuple[Body, Body]:
    """(toy, other) of pair ``pair`` () in a scene's object ``qpos`` (14,)."""
    g = lambda a: jnp.asarray(a)[pair]
    toy = Body(qpos[0:3], quat_to_mat(qpos[3:7]), g(geo.toy_lo), g(geo.toy_hi))
    oth = Body(qpos[7:10], quat_to_mat(qpos[10:14]), g(geo.oth_lo), g(geo.oth_hi))
    return toy, oth


def unit_xy(v: jax.Array) -> jax.Array:
    """Horizontal unit vector (3,) along ``v`` (3,); +x if ``v`` is (nearly) vertical."""
    v = jnp.array([v[0], v[1], 0.0])
    n = jnp.linalg.norm(v)
    return jnp.where(n > 1e-6, v / jnp.maximum(n, 1e-6), jnp.array([1.0, 0.0, 0.0]))


def perp(u: jax.Array) -> jax.Array:
    """``u`` (3,) turned 90 degrees counter-clockwise about world z, in the table plane."""
    return jnp.array([-u[1], u[0], 0.0])


DOWN = jnp.array([0.0, 0.0, -1.0])


def top_down(pos, closing) -> A.IKTarget:
    """Top-down target with a sign-free closing axis."""
    return A.IKTarget(pos, DOWN, closing, jnp.asarray(1.0), jnp.asarray(0.0))


def stack_targets(targets: list[A.IKTarget]) -> A.IKTarget:
    """K single targets -> one ``IKTarget`` with a leading (K,) axis."""
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *targets)


class Grasp(NamedTuple):
    """A top-down grasp of one body (single scene)."""

    xy: jax.Array  # (3,) grasp point with z = 0
    tcp_z: jax.Array  # tcp height at the grasp
    closing: jax.Array  # (3,) horizontal closing axis
    opening: jax.Array  # pre-grasp half opening
    fits: jax.Array  # bool: the gripper opens wide enough


def _overlap(c: jax.Array, u: jax.Array, half: jax.Array, body: Body) -> jax.Array:
    """Does the horizontal rectangle centred at ``c`` (3,) with axes (``u``, ``perp(u)``) and
    half extents ``half`` (2,) overlap the body's footprint rectangle? (separating axes, 2D)"""
    ax = unit_xy(body.mat[:, 0])
    ay = perp(ax)
    b_half = jnp.stack([body.half_width(ax), body.half_width(ay)])
    w = perp(u)
    d = body.centre - c
    sep = [jnp.abs(d @ n) > half[0] * jnp.abs(u @ n) + half[1] * jnp.abs(w @ n)
           + b_half[0] * jnp.abs(ax @ n) + b_half[1] * jnp.abs(ay @ n) for n in (u, w, ax, ay)]
    return ~(sep[0] | sep[1] | sep[2] | sep[3])


def top_under(body: Body, inner: jax.Array, c: jax.Array, u: jax.Array, half: jax.Array) -> jax.Array:
    """Height of the body's highest point under a horizontal rectangle (``_overlap``'s), or
    -1 m if it is not under it. Under a container's opening (the rectangle inside its inner
    footprint ``inner`` (3,): half x, half y, floor) only its floor counts."""
    ax = unit_xy(body.mat[:, 0])
    ay = perp(ax)
    w = perp(u)
    corners = jnp.stack([c + su * half[0] * u + sw * half[1] * w for su in (-1, 1) for sw in (-1, 1)])
    rel = corners - body.pos
    inside = jnp.all((jnp.abs(rel @ ax) < inner[0]) & (jnp.abs(rel @ ay) < inner[1]))
    top = jnp.where(inside, body.pos[2] + inner[2], body.z_range()[1])
    return jnp.where(_overlap(c, u, half, body), top, -1.0)


def squeeze_command(arm: A.Arm, cfg: ActionConfig, half: jax.Array, mass: jax.Array) -> jax.Array:
    """v2's closing command of the fingers (half opening, m): a pad stops on the held object
    at ``half`` (its half width along the closing axis) and pushes kp x (command - position),
    so commanding ``half - F / kp`` squeezes with at most F per pad. F is ``squeeze_safety``
    times what two pads need to hold ``mass`` (kg) by friction alone, within
    [``squeeze_min``, ``squeeze_max``] N (docs/arm.md, "Bounded forces")."""
    return jnp.maximum(half - squeeze_force(cfg, arm, mass) / arm.finger_kp, 0.0)


def squeeze_force(cfg: ActionConfig, arm: A.Arm, mass: jax.Array) -> jax.Array:
    """The planned squeeze per pad (N) for a held ``mass`` (kg): ``squeeze_command``'s F."""
    return jnp.clip(cfg.squeeze_safety * mass * 9.81 / (2.0 * arm.pad_friction), cfg.squeeze_min, cfg.squeeze_max)


HANDLE_HALF = 0.0125  # half the held rake handle's 2.5 cm cross-section (objects._rake)


def tool_squeeze(arm: A.Arm, cfg: ActionConfig) -> float:
    """The fingers' command (half opening, m) on the held rake's handle: v1 ``grip_closed`` (the
    actuator's force limit squeezes, 17 N per pad); v2 ``squeeze_min`` per pad, since the
    ``tool_grip`` weld carries the tool and the pads only keep their hold (17 N per pad was
    14 weights of a 0.25 kg rake)."""
    if cfg.programs == "v1":
        return float(cfg.arm.grip_closed)
    return max(HANDLE_HALF - cfg.squeeze_min / arm.finger_kp, 0.0)


# m, v4: how far the pads' footprint is grown where ``clear_grasp`` tests that no pad comes down
# on the other object: the hand's largest horizontal distance from the grasp's vertical line
# during the descent, 3.4 mm in 254 C replays of v4's pull and lift (after the dwell), rounded up
# to the millimetre (docs/actions.md, "Programs v4"). v3 tested the pads' exact rectangles: a toy
# car 0.3 mm clear of a pad at plan time was landed on by the pad 4-6 mm off its plan (285 N).
PAD_MARGIN = 0.004


def clear_grasp(arm: A.Arm, cfg: ActionConfig, g: Grasp, body: Body, other: Body, inner: jax.Array) -> Grasp:
    """v2: a grasp that keeps the palm off every object (docs/actions.md, "Programs v1 and v2").

    The fingertips go no lower than ``palm_above_tip - palm_margin`` below the grasped body's
    top (the palm's underside stays ``palm_margin`` above it) and than the same below the
    highest point of ``other`` under the palm's footprint (grown by ``palm_margin``); the
    grasp is refused (``fits`` False) if that leaves the pads less than ``min_grip`` (or, for
    a thinner body, all its v1 overlap) of the body, or if a pad (v4: its footprint grown by
    ``PAD_MARGIN``) would come down on ``other`` above the fingertips. ``inner``: the other's
    container opening (``Geometry.oth_inner`` for the other slot, zeros for a toy)."""
    zmin, zmax = body.z_range()
    reach = arm.palm_above_tip - cfg.palm_margin
    palm = jnp.asarray(arm.palm_half[::-1], jnp.float32) + cfg.palm_margin  # along, across the closing axis
    tip0 = g.tcp_z - arm.tip_below_tcp  # v1's fingertip height
    c = g.xy
    tip = jnp.maximum(tip0, zmax - reach)
    tip = jnp.maximum(tip, top_under(other, inner, c, g.closing, palm) + cfg.palm_margin - arm.palm_above_tip)
    holds = zmax - tip >= jnp.minimum(cfg.min_grip, zmax - tip0) - 1e-6
    pad = jnp.array([arm.pad_thickness / 2, arm.pad_half_x], jnp.float32)
    if is_v4(cfg):
        pad = pad + PAD_MARGIN
    off = g.opening + arm.pad_thickness / 2
    pads_free = jnp.all(jnp.stack([top_under(other, inner, c + s * off * g.closing, g.closing, pad) < tip
                                   for s in (-1.0, 1.0)]))
    return g._replace(tcp_z=tip + arm.tip_below_tcp, fits=g.fits & holds & pads_free)


def top_down_grasp(arm: A.Arm, cfg: ActionConfig, body: Body) -> Grasp:
    """Top-down grasp across the narrower horizontal side of a body's box (v1's height: the
    fingertips ``tip_clearance`` above its bottom; v2 raises it, ``clear_grasp``)."""
    ax, ay = unit_xy(body.mat[:, 0]), unit_xy(body.mat[:, 1])
    wx, wy = body.half_width(ax), body.half_width(ay)
    closing = jnp.where(wx <= wy, ax, ay)
    half = jnp.minimum(wx, wy)
    zmin, zmax = body.z_range()
    tip = zmin + jnp.minimum(cfg.tip_clearance, 0.4 * (zmax - zmin))
    opening = half + cfg.grip_margin
    c = body.centre
    return Grasp(jnp.array([c[0], c[1], 0.0]), tip + arm.tip_below_tcp, closing, opening,
                 opening <= float(arm.finger_range[1]))


def ball_extent(body: Body, radius: jax.Array) -> tuple[Callable[[jax.Array], jax.Array], jax.Array, jax.Array]:
    """The body's half width along a direction (a function), bottom and top: its box's, or for a
    ball (``radius`` > 0) its sphere's whatever its box's orientation (a ball's box turned by
    its rolling reaches up to sqrt(3) radii)."""
    zmin, zmax = body.z_range()
    ball = radius > 0
    cz = body.centre[2]
    return ((lambda d: jnp.where(ball, radius, body.half_width(d))),
            jnp.where(ball, cz - radius, zmin), jnp.where(ball, cz + radius, zmax))


def between_pads(arm: A.Arm, g: Grasp, body: Body, radius: jax.Array = 0.0) -> jax.Array:
    """v3: does ``body`` (a ball if ``radius`` > 0) lie between the pads of the grasp ``g``,
    where the closing pads meet it?

    It does when it lies in the pads' lane (across the closing axis within the pads' half width),
    within the fingers' height (fingertips to the palm's underside, ``palm_above_tip``) and,
    along the closing axis, wholly inside the pads' pre-grasp positions (``g.opening`` from the
    grasp point). A container whose opening holds the pads (its walls outside them) is not
    between them; a body under a pad or reaching past one is one the pads would land on, which
    ``clear_grasp`` refuses."""
    u, w = g.closing, perp(g.closing)
    half, zmin, zmax = ball_extent(body, radius)
    rel = body.centre - g.xy
    lane = jnp.abs(rel @ w) < half(w) + arm.pad_half_x
    tip = g.tcp_z - arm.tip_below_tcp
    level = (zmin < tip + arm.palm_above_tip) & (zmax > tip)
    return lane & level & (jnp.abs(rel @ u) + half(u) < g.opening)


def squeezed_half(arm: A.Arm, g: Grasp, half: jax.Array, other: Body, radius: jax.Array = 0.0) -> jax.Array:
    """v3: the half width (m) of the body the closing pads of ``g`` end on: the widest along the
    closing axis of the grasped body (``half``, its half width) and ``other`` (a ball if
    ``radius`` > 0) where it lies between the pads (``between_pads``). Each pad stops on the
    first body it meets and pushes a narrower one it meets first (a toy overhanging its base on
    one side) across until both pads rest on the widest, which they centre: each then pushes
    ``finger_kp`` x (this half width - the command). So ``squeeze_command`` from it bounds the
    squeeze by F whatever the pads close on (a cup around the toy take grasps: v2's command from
    the toy pressed the cup's walls with 10-22 N per pad)."""
    width = ball_extent(other, radius)[0](g.closing)
    return jnp.maximum(half, jnp.where(between_pads(arm, g, other, radius), width, 0.0))
