"""An action plugin: "drag", a tenth affordance whose success depends on the relation.

The arm grasps the base, lifts it 1 cm and drags it 20 cm towards the robot; the drag
succeeds if the base moved at least 10 cm and the toy stayed within 2 cm of its place relative
to the base (so it rode along: on top or inside, not beside). Use it with
  relaff generate drag --plugins tenth_action.py --samples 8 --out DRAG --engine native
  relaff reproduce --preset tiny --plugins tenth_action.py \\
      --set 'reproduce.actions=["lift","move","pull","push","rake","take","pour","slide","unobstruct","drag"]'
Written against the public API only (relaff_jax.sim.actions and its rule helpers, relaff_jax.sim.actions.rules).
"""
import jax.numpy as jnp

from relaff_jax.sim.actions import ActionSpec, register_action
from relaff_jax.sim.actions.rules import Reading, Settled, carry, unit_xy

# (control steps of 4 ms, the planned target the segment ends at, fingers closed): above the
# base (0), down (1), dwell, close, settle the grip, raise 1 cm (2), drag (3), lower (4), open,
# retreat (5), rest
SEGMENTS = ((150, 0, False), (100, 1, False), (40, 1, False), (60, 1, True), (25, 1, True), (40, 2, True),
            (150, 3, True), (40, 4, True), (40, 4, False), (60, 5, False), (50, 5, False))


def drag_targets(s: Settled):
    """The built-in carry of the base (6 targets), 20 cm towards the robot, 1 cm above the table."""
    return carry(s, direction=-unit_xy(s.oth.centre), distance=0.20, raise_by=0.01)


def toy_rode_along(cfg, r: Reading):
    """The base moved >= 10 cm and the toy's offset from it changed by < 2 cm (centres of mass)."""
    offset_before = r.before[0] - r.before[1]
    offset_after = r.after[0] - r.after[1]
    base_moved = jnp.linalg.norm(r.after[1, :2] - r.before[1, :2]) >= 0.10
    return base_moved & (jnp.linalg.norm(offset_after - offset_before) < 0.02)


DRAG = register_action(ActionSpec(
    name="drag", pairing="toy+base", segments=SEGMENTS, targets=drag_targets, goal=toy_rode_along,
    reads="end", grasp="other", doc="drag the base 20 cm towards the robot: the toy rode along"))
