"""Move's sweep height (``programs._program_move``): v3's tops its palm keeps off and the fixed
point that raises it over them, and the refusal of a raised sweep whose fingertips would meet a
toy fallen off a flat base; v4's raise of the fingertips over a low base the sweep crosses.
Single scene, pure JAX; docs/actions.md, "Programs v3" and "Programs v4"."""
from __future__ import annotations

import jax
import jax.numpy as jnp

from .bodies import Body, perp, unit_xy
from .templates import ActionConfig

# m, v3: a top this much beyond move's palm_margin band still counts as inside it (settled tops
# scatter by tenths of a millimetre: a car's top 2.0 cm above the palm pinned it at 5.7 N)
TOP_TOL = 0.001


def sweep_tops(cfg: ActionConfig, toy: Body, oth: Body, over: jax.Array, radius: jax.Array
               ) -> tuple[jax.Array, jax.Array]:
    """What move's v3 sweep keeps the palm off: (3,) tops (-1 m: none) and (3,) how far below
    each top the palm still meets it. The toy's top as it stands (a tilted toy, no face within
    10 degrees of level, not a ball, meets the palm with a sloped face anywhere along its
    height: a car leaning on a cup's rim, 5.7 N); the toy's own height (its top once pushed off
    its base onto the table); and, when the sweep starts over the other object, the other's top
    (a container's rim)."""
    zmin, zmax = toy.z_range()
    band = cfg.palm_margin + TOP_TOL
    level = (jnp.max(jnp.abs(toy.mat[2])) >= jnp.cos(jnp.deg2rad(10.0))) | (radius > 0)
    tops = jnp.stack([zmax, zmax - zmin, jnp.where(over, oth.z_range()[1], -1.0)])
    return tops, jnp.stack([jnp.where(level, band, zmax - zmin + band), band, band])


def sweep_raise(cfg: ActionConfig, palm: jax.Array, tops: jax.Array, depth: jax.Array) -> jax.Array:
    """How far v3 raises move's sweep (m, >= 0): from the palm's underside ``palm`` at the
    unraised sweep, every top (N,) the palm's underside is within ``palm_margin`` + ``TOP_TOL``
    above or ``depth`` (N,) below (both inclusive) lifts it to ``palm_margin`` above that top,
    re-tested at the raised height until none is. Each pass clears at least one more top, so N
    passes reach the fixed point."""
    z = palm
    for _ in range(tops.shape[0]):
        inside = (z >= tops - depth) & (z <= tops + cfg.palm_margin + TOP_TOL)
        z = jnp.maximum(z, jnp.max(jnp.where(inside, tops + cfg.palm_margin, z)))
    return z - palm


def falls_onto_fingers(cfg: ActionConfig, toy: Body, oth: Body, inner: jax.Array, raise_by: jax.Array
                       ) -> jax.Array:
    """v3: would a raised sweep push the toy off a flat base so that, fallen over on the table,
    its side (its box's least extent up) lies within ``palm_margin`` of the fingertips, which
    then ride onto it? (A 12 cm can off a 2 cm cutting board lies 6.5 cm high; with the
    fingertips at 5 cm they pressed it into the table at 42 N, 6.4 mm deep; sweeping higher,
    over its side, tipped the can over the fingers at up to 17 weights.) Such a move is refused
    at plan time. Only a toy standing on something (its bottom above ``tip_clearance``) and not
    inside a container (``inner``, the other's opening, with the toy's bottom below its rim:
    the toy falls inside it)."""
    zmin, _ = toy.z_range()
    tip = cfg.tip_clearance + 0.005 + raise_by  # the sweep's fingertips above the table
    lying = jnp.min(toy.hi - toy.lo)
    inside = jnp.any(inner[:2] > 0) & (zmin < oth.z_range()[1] - cfg.tip_clearance)
    on_flat = (zmin > cfg.tip_clearance) & ~inside
    return on_flat & (raise_by > 0) & (jnp.abs(tip - lying) < cfg.palm_margin)


# m, v4: a body the sweep crosses whose top lies from STEP_BELOW below to STEP_ABOVE above the
# fingertips (both inclusive) is a step the pads ride up onto rather than push along. C replays of
# v4 sweeps across flat bases (docs/actions.md, "Programs v4"): the pads sagged up to 1.1 mm onto a
# baking sheet's top level with them and never touched tops 2 or 4 mm below; they climbed a 5 mm
# side (a lid's) once in 61 and no side 1-3 cm high in 80
STEP_BELOW = 0.0015
STEP_ABOVE = 0.006


def sweep_crosses(arm, start: jax.Array, end: jax.Array, d: jax.Array, body: Body) -> jax.Array:
    """v4: does the closed pads' footprint (``pad_thickness`` either side of the tcp along the
    sweep's direction ``d``, ``pad_half_x`` across it), swept from ``start`` to ``end`` (3,; the
    sweep runs along ``d``), overlap the body's footprint rectangle? Two rectangles overlap
    unless one of their four edge directions separates them."""
    q = perp(d)
    reach = jnp.stack([jnp.abs(jnp.dot(end - start, d)) / 2 + arm.pad_thickness, arm.pad_half_x])
    ax = unit_xy(body.mat[:, 0])
    ay = perp(ax)
    half = jnp.stack([body.half_width(ax), body.half_width(ay)])
    rel = (body.centre - (start + end) / 2)[:2]
    apart = jnp.asarray(False)
    for u in (d, q, ax, ay):
        ra = reach[0] * jnp.abs(jnp.dot(d, u)) + reach[1] * jnp.abs(jnp.dot(q, u))
        rb = half[0] * jnp.abs(jnp.dot(ax, u)) + half[1] * jnp.abs(jnp.dot(ay, u))
        apart = apart | (jnp.abs(jnp.dot(rel, u[:2])) > ra + rb)
    return ~apart


def step_raise(cfg: ActionConfig, tip: jax.Array, top: jax.Array, crosses: jax.Array) -> jax.Array:
    """v4: how far to raise move's sweep (m, >= 0) whose fingertips, ``tip`` above the table,
    cross (``crosses``) a body whose ``top`` is a step they would ride onto (``STEP_BELOW`` below
    to ``STEP_ABOVE`` above them): the fingertips then pass as high above that top as they pass
    above the table (``tip_clearance`` + 5 mm), sweeping the toy off it rather than dragging
    the base along under the pads."""
    step = crosses & (top >= tip - STEP_BELOW) & (top <= tip + STEP_ABOVE)
    return jnp.where(step, top + cfg.tip_clearance + 0.005 - tip, 0.0)
