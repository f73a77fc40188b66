"""The bounds the physics of executed programs keeps, stated once.

The programs (v2) promise them and their reasoning is in docs/arm.md, "Bounded forces"; the
audit (``data/audit.py``, ``relaff audit``) checks them on a dataset's rollouts and
tests/sim/test_programs_v2.py on replayed scenes. All are read by ``native.probe.Probe``.
"""
SUSTAIN_STEPS = 25  # control steps (0.1 s at 4 ms): a force held this long is a press, not an impact
PRESS_WEIGHTS = 10.0  # the force on an object held over SUSTAIN_STEPS <= this x the heavier object's weight
PENETRATION_M = 0.003  # no contact with an object deeper than this held over SUSTAIN_STEPS (impacts: reported)
PALM_CONTACT_STEPS = 0  # steps with a contact between the hand body (palm) and an object
MOVING_M_S = 0.02  # an object not held by the hand at the measuring step (SceneConfig.rest_speed)
