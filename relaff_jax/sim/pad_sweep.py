"""Programs v4: what the pads sweep through after they come down, tested at plan time.

Takes the arm tables, a top-down ``bodies.Grasp`` and the two bodies of a scene; gives two
tests that ``programs`` uses to refuse a grasp (docs/actions.md, "Programs v4"):

- ``wall_between_pads``: take's closing pads would end on a body that stands between them
  without lying wholly between them (a container's wall with one pad inside it and one
  outside, a box beside the toy). ``squeezed_half`` bounds the squeeze only for a body wholly
  between the pads; here the pads end on the toy and the wall together, wider than the command
  made for the toy, and each presses ``finger_kp`` x the shortfall.
- ``carry_meets_toy``: the pads of a drag's base grasp would meet the toy standing beside the
  base on their way from the grasp to the end of the carry (the toy as it stands, its top above
  the grasp's fingertips), and push it ahead of them or come down on it at the end.

Both grow the pads' footprint by ``bodies.PAD_MARGIN``, the hand's tracking error. Single
scene, pure JAX; the caller vmaps and jits.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from . import arm as A
from .bodies import PAD_MARGIN, Body, Grasp, between_pads, top_under

# samples along a drag's carry at which the pads' footprint is tested: the carry (25-30 cm)
# in steps shorter than the pad's 1.6 cm thickness grown by the margin on both sides
CARRY_SAMPLES = 33


def wall_between_pads(arm: A.Arm, g: Grasp, other: Body, inner: jax.Array) -> jax.Array:
    """() bool: does ``other`` stand between the pads of the grasp ``g`` (the region between their
    pre-grasp inner faces, in their lane, grown by ``PAD_MARGIN``) above the fingertips, without
    lying wholly between them (``between_pads``)? Under a container's opening only its floor
    counts (``top_under``): pads that both come down inside the opening pass."""
    tip = g.tcp_z - arm.tip_below_tcp
    half = jnp.stack([g.opening, jnp.asarray(arm.pad_half_x, jnp.float32)]) + PAD_MARGIN
    return (top_under(other, inner, g.xy, g.closing, half) >= tip) & ~between_pads(arm, g, other)


def carry_meets_toy(arm: A.Arm, g: Grasp, base: Body, toy: Body, end: jax.Array) -> jax.Array:
    """() bool: would a pad of the base grasp ``g``, carried from the grasp point to ``end`` (3,),
    pass over the toy's footprint (grown by ``PAD_MARGIN``) where the toy's top is above the
    grasp's fingertips? Only a toy standing on the table counts (its bottom within 5 mm of the
    base's): one on or in the base moves with it. The carry is raised by ``drag_raise`` (2 cm), so
    a toy a little taller than the fingertips is passed over and then landed on where it still
    stands under a pad at the end, or pushed by the base into the pad's way; a taller one is
    pushed by the pad's side."""
    tip = g.tcp_z - arm.tip_below_tcp
    off = g.opening + arm.pad_thickness / 2
    pad = jnp.array([arm.pad_thickness / 2, arm.pad_half_x], jnp.float32) + PAD_MARGIN
    s = jnp.linspace(0.0, 1.0, CARRY_SAMPLES)
    path = g.xy[None, :] + s[:, None] * (end - g.xy)[None, :]
    under = jax.vmap(lambda c: jnp.stack([top_under(toy, jnp.zeros(3), c + k * off * g.closing, g.closing, pad)
                                          for k in (-1.0, 1.0)]))(path)
    standing = toy.z_range()[0] < base.z_range()[0] + 0.005
    return standing & jnp.any(under >= tip)
