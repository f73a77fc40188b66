"""One settled scene as the camera sees it: ``SceneGeoms``, a pytree of geoms.

Takes MuJoCo geom types, segment labels, sizes and poses (or a native MjModel/MjData);
gives a checked ``SceneGeoms`` (static types and labels, (..., G, 3) sizes and positions,
(..., G, 3, 3) rotations) and ``bounding_radius`` per geom type.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.constants import OBJECT_SEGMENTS, SEG_BACKGROUND, SEG_NONE, SEG_OTHER, SEG_TOY

# MuJoCo mjtGeom values we can render.
GEOM_PLANE, GEOM_SPHERE, GEOM_CAPSULE, GEOM_BOX = 0, 2, 3, 6
SUPPORTED_GEOMS = {GEOM_PLANE: "plane", GEOM_SPHERE: "sphere", GEOM_CAPSULE: "capsule", GEOM_BOX: "box"}


@functools.partial(
    jax.tree_util.register_dataclass,
    data_fields=["size", "xpos", "xmat"],
    meta_fields=["geom_type", "geom_seg"],
)
@dataclasses.dataclass(frozen=True)
class SceneGeoms:
    """Geoms of one settled scene (a pytree; the two tuples are static).

    geom_type: (G,) MuJoCo mjtGeom ints (plane 0, sphere 2, capsule 3, box 6)
    geom_seg:  (G,) segment label: 0 table/background, 1 toy, 2 other object, -1 never rendered
    size:      (G, 3) MuJoCo geom_size
    xpos:      (G, 3) geom centres, robot frame
    xmat:      (G, 3, 3) rotations, columns = geom axes in the robot frame
    """

    geom_type: tuple[int, ...]
    geom_seg: tuple[int, ...]
    size: Any
    xpos: Any
    xmat: Any


def make_scene(geom_type, geom_seg, size, xpos, xmat) -> SceneGeoms:
    """Build a ``SceneGeoms`` with checked static info; ``xmat`` may be (..., G, 9)."""
    gt = tuple(int(t) for t in np.asarray(geom_type).ravel())
    gs = tuple(int(s) for s in np.asarray(geom_seg).ravel())
    if len(gt) != len(gs):
        raise ValueError(f"geom_type has {len(gt)} entries but geom_seg has {len(gs)}")
    for i, (t, s) in enumerate(zip(gt, gs)):
        if s not in (SEG_NONE, SEG_BACKGROUND, SEG_TOY, SEG_OTHER):
            raise ValueError(f"geom {i}: segment label {s} not in (-1, 0, 1, 2)")
        if s != SEG_NONE and t not in SUPPORTED_GEOMS:
            raise ValueError(
                f"geom {i}: mjtGeom {t} cannot be rendered (supported: {SUPPORTED_GEOMS}); "
                "give it segment -1 or use a supported primitive"
            )
        if s in OBJECT_SEGMENTS and t == GEOM_PLANE:
            raise ValueError(f"geom {i}: a plane cannot be part of object segment {s}")
    xmat = jnp.asarray(xmat, jnp.float32)
    xmat = xmat.reshape(xmat.shape[:-1] + (3, 3)) if xmat.shape[-1] == 9 else xmat
    size = jnp.asarray(size, jnp.float32)
    xpos = jnp.asarray(xpos, jnp.float32)
    g = len(gt)
    if size.shape[-2:] != (g, 3) or xpos.shape[-2:] != (g, 3) or xmat.shape[-3:] != (g, 3, 3):
        raise ValueError(
            f"expected size/xpos (..., {g}, 3) and xmat (..., {g}, 3, 3), got "
            f"{size.shape}, {xpos.shape}, {xmat.shape}"
        )
    return SceneGeoms(gt, gs, size, xpos, xmat)


def scene_layout(geom_type, geom_seg):
    """``build(size, xpos, xmat) -> SceneGeoms`` for one geom layout, checked once here by
    ``make_scene``; ``build`` takes the arrays as given (one scene's, inside jit and vmap)."""
    g = len(np.asarray(geom_type).ravel())
    static = make_scene(geom_type, geom_seg, np.zeros((g, 3)), np.zeros((g, 3)), np.tile(np.eye(3), (g, 1, 1)))
    return lambda size, xpos, xmat: SceneGeoms(static.geom_type, static.geom_seg, size, xpos, xmat)


def scene_from_mujoco(model, data, geom_seg) -> SceneGeoms:
    """``SceneGeoms`` of a native MuJoCo (MjModel, MjData) after ``mj_forward``."""
    return make_scene(model.geom_type, geom_seg, model.geom_size, data.geom_xpos, data.geom_xmat)


def bounding_radius(geom_type: int, size):
    """Radius of a sphere about the geom centre enclosing the geom. size: (..., 3)."""
    if geom_type == GEOM_SPHERE:
        return size[..., 0]
    if geom_type == GEOM_CAPSULE:
        return size[..., 0] + size[..., 1]
    if geom_type == GEOM_BOX:
        return jnp.linalg.norm(size, axis=-1)
    raise ValueError(f"no bounding sphere for mjtGeom {geom_type} ({SUPPORTED_GEOMS.get(geom_type)})")
