"""The nine actions of Table I declared as ``ActionSpec``s, in ``constants.ACTIONS`` order.

Each refers to today's functions: the template rows of ``templates.py``, the target rules of
``programs.program`` and the goals of ``labels.goals`` (every built-in goal reads one after
state: the lift-type ones the measuring step, the others the end), so the tables and rules the
registry gives equal the hard-wired ones bit for bit (``tests/sim/test_action_registry.py``).
"""
from __future__ import annotations

import functools

from relaff_jax.constants import ACTIONS, PAIRING, PAIRINGS, TOY_MANIPULATED
from relaff_jax.sim import templates as T

from .rules import Reading, Settled, as_outcome
from .spec import ActionSpec
from relaff_jax.sim.programs import program
from relaff_jax.sim.labels import goals


def _targets(name: str, s: Settled):
    return program(name, s.arm, s.cfg, s.geo, s.pair, s.qpos)


def _goal(name: str, cfg, r: Reading):
    return goals(cfg, as_outcome(r))[ACTIONS.index(name)]


_ROWS = {"lift": T._LIFT, "move": T._MOVE, "pull": T._DRAG, "push": T._DRAG, "rake": T._SWEEP,
         "take": T._LIFT, "pour": T._TILT, "slide": T._TILT, "unobstruct": T._DRAG}
_GRASP = {"take": "toy", "move": "none", "rake": "tool"}
_MEASURE_READ = ("lift", "take", "pour", "slide")
_DOC = {
    "lift": "grasp the base, lift 25 cm: toy and base rose >= 5 cm",
    "move": "sweep the toy aside along the table: it moved >= 8 cm from the base",
    "pull": "carry the base 25 cm towards the robot: both 10 cm closer",
    "push": "carry the base 25 cm away: both 10 cm farther",
    "rake": "pull the toy with the held rake: toy 10 cm closer",
    "take": "grasp the toy, lift: toy rose, the base did not",
    "pour": "lift the base and tilt 60 degrees: both still rose",
    "slide": "lift the base and tilt: the toy slid off, not lifted",
    "unobstruct": "carry the obstacle aside: the toy reachable now, not before",
}


def _spec(name: str) -> ActionSpec:
    return ActionSpec(name=name, pairing=PAIRINGS[PAIRING[name]], segments=tuple(_ROWS[name]),
                      targets=functools.partial(_targets, name), goal=functools.partial(_goal, name),
                      reads="measure" if name in _MEASURE_READ else "end", grasp=_GRASP.get(name, "other"),
                      manipulates="toy" if name in TOY_MANIPULATED else "other",
                      reach=name == "unobstruct", measure=T.TEMPLATES[name].measure, doc=_DOC[name])


BUILTINS = tuple(_spec(a) for a in ACTIONS)
