"""``ActionSpec``: one action declared as data (no JAX at import).

A spec names the action, the object pairing it is tried on, its motor-program template (the
segments: control steps, the planned tcp target each ends at, fingers closed or open), the
step its goal is first read at, its target rule (settled scene -> tcp targets), its goal rule
(object states before and after -> label), which reading of the after state the goal uses,
and how the closed gripper holds what it grasps. ``check_fields`` checks what can be checked
without JAX; ``check.py`` traces the rules once.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable

from relaff_jax.constants import PAIRINGS
from relaff_jax.errors import UserError

# How a closed gripper holds (simulate.run_program_locked's grasp lock): "other" locks onto the
# base or obstacle, "toy" onto the toy, "none" never locks, "tool": the rake is held from the start.
GRASP_KINDS = ("other", "toy", "none", "tool")
GRASP_CODE = {"other": 1, "toy": 2, "none": 0, "tool": 0}
# Which after state a goal reads: "measure" the objects at the measuring step (the lift-type
# goals), "end" at the end of the run; with programs v2 both are the first step at rest.
READINGS = ("measure", "end")
# Which object the program manipulates (moves or grasps): its nine PCA values come first in the
# action's state (``learn.states.manipulated_first_order``). None: the one the grasp holds ("toy"
# for grasp "toy", else "other").
MANIPULATED = ("toy", "other")
REQUIRED = ("name", "pairing", "segments", "targets", "goal")


@dataclasses.dataclass(frozen=True)
class ActionSpec:
    """One action. Fields:

    name: a letter, then letters, digits or ``_``; pairing: one of ``constants.PAIRINGS``;
    segments: ``((steps, target, closed), ...)`` at most ``templates.N_SEGMENTS`` segments of
      ``steps`` >= 1 control steps (4 ms), each ending at planned target ``target`` (0 ..
      ``N_TARGETS - 1``) with the fingers closed (True) or open (False); the segments and one
      step per unused segment fit in ``templates.N_STEPS``;
    targets: ``targets(s: Settled) -> Program``, jnp-traceable, one scene: ``s.toy``/``s.oth``
      the settled bodies, ``s.qpos (14,)``, ``s.pair ()``, ``s.arm``, ``s.cfg``; the Program's
      ``targets`` are K <= N_TARGETS tcp targets (``IKTarget``: pos, approach, closing (K, 3),
      closing_weight, closing_signed (K,); K > the largest target index of the segments), ``opening ()`` the pre-grasp half opening,
      ``ok ()`` bool geometric preconditions, ``direction (3,)``, ``grip_closed ()`` the
      fingers' closing command;
    goal: ``goal(cfg: ActionConfig, r: Reading) -> () bool``, jnp-traceable, one scene:
      ``r.before``/``r.after`` (2, 3) centres of mass of (toy, other), ``r.direction`` (3,),
      ``r.reach_before``/``r.reach_after`` () unobstruct's reachability of the toy;
    reads: ``"measure"`` (after = the objects at the measuring step) or ``"end"`` (at the end);
    grasp: one of ``GRASP_KINDS``; manipulates: one of ``MANIPULATED``, the object the program
      moves or grasps, first in the state the action's predictor learns from (None: the one
      the grasp holds, ``manipulated``); reach: evaluate the toy's reachability before and after;
    measure: the control step the goal is first read at (None: the last step of the segments);
    doc: one line for listings.
    """

    name: str = None
    pairing: str = None
    segments: tuple = None
    targets: Callable[..., Any] = None
    goal: Callable[..., Any] = None
    reads: str = "end"
    grasp: str = "other"
    manipulates: str | None = None
    reach: bool = False
    measure: int | None = None
    doc: str = ""

    def __post_init__(self):  # a bad spec is refused where it is made, naming the field
        check_fields(self)

    @property
    def pairing_id(self) -> int:
        return PAIRINGS.index(self.pairing)

    @property
    def manipulated(self) -> str:
        """``"toy"`` or ``"other"``: the declared ``manipulates``, else the object the grasp holds."""
        if self.manipulates is not None:
            return self.manipulates
        return "toy" if self.grasp == "toy" else "other"


def _bad(spec_name: Any, field: str, why: str) -> UserError:
    return UserError(f"action {spec_name!r}: field {field}: {why}")


def check_fields(spec: Any) -> None:
    """The fields' types and ranges (no JAX); a ``UserError`` naming the field."""
    import re

    # the built-ins' rules import JAX: the command line's checks read this module
    from relaff_jax.sim.templates import N_SEGMENTS, N_STEPS, N_TARGETS

    if not isinstance(spec, ActionSpec):
        raise UserError(f"register_action expects an ActionSpec, got {type(spec).__name__}")
    name = spec.name
    for f in REQUIRED:
        if getattr(spec, f) is None:
            raise _bad(name, f, "missing (required: " + ", ".join(REQUIRED) + ")")
    if not isinstance(name, str) or not re.match(r"^[A-Za-z][A-Za-z0-9_]*$", name):
        raise _bad(name, "name", "expected a letter, then letters, digits or _")
    if spec.pairing not in PAIRINGS:
        raise _bad(name, "pairing", f"unknown pairing {spec.pairing!r}; valid: {', '.join(PAIRINGS)}")
    segs = spec.segments
    if not isinstance(segs, (tuple, list)) or not segs:
        raise _bad(name, "segments", "expected a non-empty sequence of (steps, target, closed)")
    for i, s in enumerate(segs):
        ok = isinstance(s, (tuple, list)) and len(s) == 3 and all(
            isinstance(v, int) and not isinstance(v, bool) for v in s[:2]) and isinstance(s[2], bool)
        if not ok:
            raise _bad(name, "segments", f"segment {i} is {s!r}, expected (steps: int, target: int, closed: bool)")
        if s[0] < 1:
            raise _bad(name, "segments", f"segment {i} has {s[0]} steps, expected >= 1")
        if not 0 <= s[1] < N_TARGETS:
            raise _bad(name, "segments", f"segment {i} ends at target {s[1]}, expected 0 .. {N_TARGETS - 1}")
    if len(segs) > N_SEGMENTS:
        raise _bad(name, "segments", f"{len(segs)} segments, the compiled programs hold {N_SEGMENTS}")
    need = sum(s[0] for s in segs) + N_SEGMENTS - len(segs)
    if need > N_STEPS:
        raise _bad(name, "segments", f"the template needs {need} control steps, longer than the compiled "
                                     f"step budget of {N_STEPS}")
    for field in ("targets", "goal"):
        if not callable(getattr(spec, field)):
            raise _bad(name, field, f"{getattr(spec, field)!r} is not a function")
    if spec.reads not in READINGS:
        raise _bad(name, "reads", f"{spec.reads!r}; valid: {', '.join(READINGS)}")
    if spec.grasp not in GRASP_KINDS:
        raise _bad(name, "grasp", f"{spec.grasp!r}; valid: {', '.join(GRASP_KINDS)}")
    if (spec.grasp == "tool") != (spec.pairing == "toy+rake"):
        raise _bad(name, "grasp", "'tool' (the held rake) goes with the pairing toy+rake and only with it")
    if spec.manipulates is not None and spec.manipulates not in MANIPULATED:
        raise _bad(name, "manipulates", f"{spec.manipulates!r}; valid: {', '.join(MANIPULATED)} (or None: the "
                                        "object the grasp holds)")
    held = {"toy": "toy", "other": "other", "tool": "other"}.get(spec.grasp)
    if spec.manipulates is not None and held is not None and spec.manipulates != held:
        raise _bad(name, "manipulates", f"{spec.manipulates!r}, but the closed gripper holds "
                                        f"{'the toy' if held == 'toy' else 'the other object'} (grasp {spec.grasp!r})")
    if not isinstance(spec.reach, bool):
        raise _bad(name, "reach", f"expected True or False, got {spec.reach!r}")
    end = sum(s[0] for s in segs) - 1
    if spec.measure is not None and (isinstance(spec.measure, bool) or not isinstance(spec.measure, int)
                                     or not 0 <= spec.measure <= end):
        raise _bad(name, "measure", f"{spec.measure!r}, expected a control step in 0 .. {end} (or None)")
    if not isinstance(spec.doc, str):
        raise _bad(name, "doc", "expected a string")
