"""Geometry helpers of the built-in programs (``bodies.py``), re-exported for target rules."""
from relaff_jax.sim.bodies import perp, stack_targets, top_down, unit_xy  # noqa: F401
