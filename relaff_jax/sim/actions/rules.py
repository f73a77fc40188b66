"""What a rule sees and the building blocks of target rules (JAX).

``Settled``: one settled scene as a target rule sees it, inside the traced plan; ``Reading``:
what a goal rule sees; ``plan_program`` (a spec's target rule, padded to ``N_TARGETS``) and
``goal_row`` (every action's goal on one outcome) are what the compiled programs call. The
helpers (``base_grasp``, ``carry``, ``lift``, ``transit_z``) are the built-in programs' own
pieces (``programs.py``), wrapped, so a user's target rule can reuse them; the geometry helpers
(``top_down``, ``stack_targets``, ``unit_xy``, ``perp``) are ``bodies.py``'s, imported here for it.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from relaff_jax.sim import arm as A
from relaff_jax.sim import programs as P
from relaff_jax.sim.bodies import Body, Geometry, Grasp
from relaff_jax.sim.bodies import perp, stack_targets, top_down, unit_xy  # noqa: F401 (a plugin's helpers)
from relaff_jax.sim.labels import Outcome
from relaff_jax.sim.templates import N_TARGETS, ActionConfig

from .spec import ActionSpec

Program = P.Program
IKTarget = A.IKTarget


class Settled(NamedTuple):
    """One settled scene, as a target rule sees it: the arm tables, the config, the pairs'
    geometry, the pair index () int32 and the settled object qpos (14,) float32 (toy's free
    joint, then the other object's). ``scene`` gives the bodies (``toy``, ``oth``: box pose
    and half sizes), the other's container opening and both masses."""

    arm: A.Arm
    cfg: ActionConfig
    geo: Geometry
    pair: jax.Array
    qpos: jax.Array

    @property
    def scene(self) -> P.Scene:
        return P._scene(self.geo, self.pair, self.qpos)

    @property
    def toy(self) -> Body:
        return self.scene.toy

    @property
    def oth(self) -> Body:
        return self.scene.oth


class Reading(NamedTuple):
    """What a goal rule reads, one scene: ``before``/``after`` (2, 3) centres of mass of (toy,
    other) before the action and after it (the spec's ``reads``: at the measuring step or at
    the end), ``direction`` (3,) the program's, ``reach_before``/``reach_after`` () bool the
    toy's reachability (False unless the spec's ``reach``)."""

    before: jax.Array
    after: jax.Array
    direction: jax.Array
    reach_before: jax.Array
    reach_after: jax.Array


def base_grasp(s: Settled) -> tuple[Grasp, jax.Array]:
    """The built-in grasp of the other object (top-down across its narrow side; v2 palm clear)
    and its closing command."""
    return P._base_grasp(s.arm, s.cfg, s.scene)


def transit_z(s: Settled) -> jax.Array:
    """() the tcp height that clears both objects by ``cfg.clearance``."""
    return P._transit_z(s.arm, s.cfg, s.toy, s.oth)


def carry(s: Settled, direction: jax.Array, distance: float, raise_by: float) -> Program:
    """The built-in carry of the other object (pull, push, unobstruct): grasp it, raise by
    ``raise_by``, carry ``distance`` along ``direction`` (3,), lower, open, retreat (6 targets)."""
    return P._program_drag(s.arm, s.cfg, s.scene, direction=direction, distance=distance, raise_by=raise_by)


def lift(s: Settled, grasp_toy: bool = False, tilt: bool = False) -> Program:
    """The built-in grasp-and-lift (lift, take with ``grasp_toy``, pour/slide with ``tilt``)."""
    return P._program_lift(s.arm, s.cfg, s.scene, grasp_toy=grasp_toy, tilt=tilt)


def plan_program(spec: ActionSpec, arm: A.Arm, cfg: ActionConfig, geo: Geometry, pair: jax.Array,
                 qpos: jax.Array) -> Program:
    """The spec's target rule on one scene, its targets padded to ``N_TARGETS`` (repeating the last)."""
    prog = spec.targets(Settled(arm, cfg, geo, pair, qpos))
    k = prog.targets.pos.shape[0]
    if k == N_TARGETS:
        return prog
    pad = lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], N_TARGETS - k, axis=0)])
    return prog._replace(targets=jax.tree_util.tree_map(pad, prog.targets))


def reading(spec: ActionSpec, o: Outcome) -> Reading:
    """The spec's view of an outcome (one scene)."""
    after = o.com_m if spec.reads == "measure" else o.com_end
    return Reading(o.com0, after, o.direction, o.reach_before, o.reach_after)


def goal_row(specs: tuple[ActionSpec, ...], cfg: ActionConfig, o: Outcome) -> jax.Array:
    """(A,) bool: every action's goal on one scene's outcome, in the registry's order."""
    return jnp.stack([jnp.asarray(s.goal(cfg, reading(s, o))).astype(bool).reshape(()) for s in specs])


def as_outcome(r: Reading) -> Outcome:
    """A reading as ``labels.Outcome`` (both after states the reading's) for the built-in rules."""
    return Outcome(r.before, r.after, r.after, r.direction, r.reach_before, r.reach_after)


