"""The bounds the physics of executed programs keeps, stated once.

The programs (v2) promise them and their reasoning is in docs/arm.md, "Bounded forces"; the
audit (``data/audit.py``, ``relaff audit``) checks them on a dataset's rollouts and
tests/sim/test_programs_v2.py on replayed scenes. All are read by ``native.probe.Probe``.
"""
import math

SUSTAIN_STEPS = 25  # control steps (0.1 s at 4 ms): a force held this long is a press, not an impact
PRESS_WEIGHTS = 10.0  # the force on an object held over SUSTAIN_STEPS <= this x the heavier object's weight ...
PRESS_FLOOR_N = 12.0  # ... or <= this many newtons: two pads at the least squeeze (ActionConfig.squeeze_min,
# 5 N) plus a light pair's weight, which is more than 10 weights of a pair under 120 g (a block on a placemat)


def press_ok(press_n, weight_n):
    """Is a held force (N) within the bound, for the heavier object's weight (N)? Arrays broadcast."""
    return (press_n <= PRESS_WEIGHTS * weight_n) | (press_n <= PRESS_FLOOR_N)
PENETRATION_M = 0.003  # no contact with an object deeper than this held over SUSTAIN_STEPS (impacts: reported)
PALM_CONTACT_STEPS = 0  # steps with a contact FROM ABOVE between the hand body (palm) and an object
PALM_FORCE_N = 0.5  # ... carrying more than this normal force (N): under the lightest object's weight (the 60 g
# ball, 0.59 N) a touch holds nothing down; the audits' palm contacts from above are presses of 5.7 N and more or
# single steps at 0.00 N (a tilted rim grazing the palm's underside, 0.13 mm deep, separating)
PALM_ABOVE_DEG = 45.0  # a palm contact is from above when its normal is within this angle of vertical
PALM_ABOVE_COS = math.cos(math.radians(PALM_ABOVE_DEG))  # |n_z| >= this: the palm presses down (or an
# object's top edge is under it); the rest are from the side: the palm pushing (move's sweep against a tall base)
MOVING_M_S = 0.02  # an object not held by the hand at the measuring step (SceneConfig.rest_speed)
