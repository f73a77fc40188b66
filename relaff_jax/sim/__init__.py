"""Simulation: the object library, one MJX world for every pair, scene sampling and settling,
the 6-DOF arm, the nine motor programs and their physics labels, and MuJoCo C references.

Modules, in pipeline order:

- ``objects``: the 29-object library (``ObjectSpec`` per name) and the 124 scene pairs.
- ``world``: ``PhysicsConfig`` and ``build_world``: one batched MJX model for every pair.
- ``contacts``: ``contacts(d)``, the one reader of MJX's contact list.
- ``scenes``: ``SceneConfig``; placement sampling, settling, relation labels (``Scenes``).
- ``geometry``: rotations (``quat_to_mat``, ``axis_rotation``).
- ``arm_model``: the arm's names, ``ArmConfig`` and ``Arm`` tables from a compiled model.
- ``kinematics``: forward kinematics and the IK (``solve_ik``, ``solve_ik_path``).
- ``arm``: the arm in one import (re-exports the two above), held tools, gripper commands,
  motor-program control, finger contacts.
- ``templates``: ``ActionConfig`` and the timing templates of the nine motor programs.
- ``bodies``: the settled objects as the programs see them (boxes, grasps).
- ``programs``: the nine motor programs (tcp targets) and unobstruct's reachability.
- ``planning``: ``setup`` (action world, home pose) and ``make_plan_fn`` (batched IK).
- ``labels``: the outcome rules of Table I (``goals``).
- ``simulate``: planned programs executed in MJX with grasp locks, then labelled.
- ``rollouts``: ``make_action_fn`` / ``jitted_action_fn`` and ``make_rollout_fn`` (datasets).
- ``native``: MuJoCo C references (``settle_native``, ``replay_native``) for cross-checks.

The config and entry-point names other stages use are re-exported here.
"""
from relaff_jax.sim.arm_model import ArmConfig
from relaff_jax.sim.native import replay_native, settle_native
from relaff_jax.sim.rollouts import allowed_pairs, jitted_action_fn, make_action_fn, make_rollout_fn
from relaff_jax.sim.scenes import SceneConfig
from relaff_jax.sim.templates import ActionConfig
from relaff_jax.sim.world import PhysicsConfig, build_world

__all__ = [
    "ActionConfig", "ArmConfig", "PhysicsConfig", "SceneConfig", "allowed_pairs", "build_world",
    "jitted_action_fn", "make_action_fn", "make_rollout_fn", "replay_native", "settle_native",
]
