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
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import arm as A
from . import objects as lib
from . import world as wd
from .geometry import quat_to_mat
from .templates import ActionConfig


@dataclasses.dataclass(frozen=True, eq=False)
class Geometry:
    """Per-pair object geometry in each object's own frame (origin at the footprint's bottom
    centre; rakes: the grip point). (P, 3) bounding boxes ``toy_lo``/``toy_hi`` and
    ``oth_lo``/``oth_hi``; rake head: ``head_x0`` near face x, ``head_y`` (P, 2) y range."""

    pairing: np.ndarray
    toy_lo: np.ndarray
    toy_hi: np.ndarray
    oth_lo: np.ndarray
    oth_hi: np.ndarray
    head_x0: np.ndarray
    head_y: np.ndarray


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
        rows.append((lib.PAIRINGS.index(pairing), tl, th, ol, oh, head_x0, head_y))
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


def top_down_grasp(arm: A.Arm, cfg: ActionConfig, body: Body) -> Grasp:
    """Top-down grasp across the narrower horizontal side of a body's box."""
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
