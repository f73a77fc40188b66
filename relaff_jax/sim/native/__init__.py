"""The native engine: MuJoCo C (``mujoco.batch`` on a thread pool) running what the MJX programs run.

Takes the same planned programs and settled scenes as the MJX stages (``sim.planning``,
``sim.scenes``); gives the same labels, and the physics of each rollout, for datasets
(``--engine native``), cross-checks and the audit.

- ``program.py``: what the C executions share: program inputs, the weld relpose, labels;
- ``settle.py``: scenes settled in C on the thread pool (the native engine's settle);
- ``batch.py``: planned programs executed in C batches (``execute_native``, ``default_threads``);
- ``reference.py``: one scene at a time in C (``settle_native``, ``replay_native``), the
  references the MJX stages are checked against;
- ``probe.py``: a rollout's physics step by step from C contacts (the audit's probe);
- ``forces.py``: the physics of executed programs in the keys of the programs' tests and
  the force benchmark.

Nothing is imported here (every module imports MuJoCo and the simulation).
"""
