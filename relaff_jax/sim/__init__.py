"""Simulation: the object library, one MJX world for every pair, scene sampling and settling,
the 6-DOF arm, the nine motor programs and their physics labels, and MuJoCo C references.

Modules, in pipeline order:

- ``objects``: the 29-object library (``ObjectSpec`` per name), ``ObjectSet`` (the objects a
  run uses, the built-ins' 124 scene pairs by default) and the active set.
- ``object_library``: object library files (TOML/JSON), their checks, the dataset record.
- ``world``: ``build_world``: one batched MJX model for every pair.
- ``contacts``: ``contacts(d)``, the one reader of MJX's contact list.
- ``scenes``: placement sampling, settling, relation labels (``Scenes``).
- ``still``: programs v4's check that a settled scene stays still (MJX; C in ``native/settle``).
- ``geometry``: rotations (``quat_to_mat``, ``axis_rotation``).
- ``arm_model``: the arm's names and ``Arm`` tables from a compiled model.
- ``kinematics``: forward kinematics and the IK (``solve_ik``, ``solve_ik_path``).
- ``arm``: the arm in one import (re-exports the two above), held tools, gripper commands,
  motor-program control, finger contacts.
- ``templates``: the timing templates of the nine motor programs.
- ``bodies``: the settled objects as the programs see them (boxes, grasps).
- ``programs``: the nine motor programs (tcp targets) and unobstruct's reachability.
- ``sweep``: move's sweep height under programs v3 and v4 (tops, fixed point, refusal, step).
- ``planning``: ``setup`` (action world, home pose) and ``make_plan_fn`` (batched IK).
- ``labels``: the outcome rules of Table I (``goals``).
- ``simulate``: planned programs executed in MJX with grasp locks, then labelled.
- ``rollouts``: ``make_action_fn`` / ``jitted_action_fn`` and ``make_rollout_fn`` (datasets).
- ``native/``: the native engine, the motor programs and the settle in MuJoCo C batches, and the
  one-scene C references (``settle_native``, ``replay_native``) for cross-checks (``native/__init__.py``).

Nothing is imported here: ``sim.actions.registry`` and ``sim.object_library``, which the command
line reads to check its arguments, come without JAX and MuJoCo. Import a name from the module that
defines it (``from relaff_jax.sim.rollouts import make_rollout_fn``); the settings are
``relaff_jax.config.action``.
"""
