"""Settings and timing of the nine motor programs: ``ActionConfig`` and the templates.

Takes nothing; gives ``ActionConfig`` (static settings of the motor programs and of the
outcome rules), ``TEMPLATES`` (per action a ``Template``: segment lengths, IK target per
segment, fingers closed or open, the measuring step) and the same as (9, ...) tables in
``ACTIONS`` order (``TPL_STEPS``, ``TPL_TARGET``, ``TPL_CLOSED``, ``TPL_MEASURE``, ``GRASPS``)
that the compiled programs index with the traced action id. Motor programs: docs/actions.md.
"""
from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.config.action import ActionConfig, V2_FIELDS
from relaff_jax.config import to_dict


class Template(NamedTuple):
    """Static part of a motor program: per segment its length (control steps of one physics
    step), the IK target it ends at (index into the planned targets) and whether the fingers
    close (True) or open to the pre-grasp width (False) during it; ``measure``: the control
    step at which lift-type goals are read (the end of the action's own program).

    Every template is padded to ``N_SEGMENTS`` segments and ``N_STEPS`` control steps (a final
    rest), so one compiled simulation serves all nine actions."""

    seg_steps: tuple[int, ...]
    target: tuple[int, ...]
    closed: tuple[bool, ...]
    measure: int


N_SEGMENTS = 11
N_STEPS = 815  # 3.26 s at the 4 ms step (the longest template, pour/slide, plus padding)
N_TARGETS = 6


def _template(rows, n_segments: int = N_SEGMENTS, n_steps: int = N_STEPS) -> Template:
    steps, target, closed = (list(c) for c in zip(*rows))
    measure = sum(steps) - 1
    while len(steps) < n_segments:  # 1-step dwells, then the last one rests until n_steps
        steps.append(1)
        target.append(target[-1])
        closed.append(closed[-1])
    steps[-1] += n_steps - sum(steps)
    assert len(steps) == n_segments and min(steps) >= 1, rows
    return Template(tuple(steps), tuple(target), tuple(closed), measure)


# Grasp-and-lift: home -> above (0), down to the grasp (1), dwell, close, lift (2), hold.
_LIFT = [(150, 0, False), (100, 1, False), (40, 1, False), (60, 1, True), (25, 1, True),
         (125, 2, True), (60, 2, True)]
# Pour/slide: the same, then tilt (3) and hold while a loose toy slides off and lands.
_TILT = _LIFT + [(100, 3, True), (150, 3, True)]
# Carry along the table: grasp, raise a little (2), carry (3), lower (4), open, retreat (5).
_DRAG = _LIFT[:5] + [(40, 2, True), (150, 3, True), (40, 4, True), (40, 4, False), (60, 5, False),
                     (50, 5, False)]
# Rake: with the held rake above the start (0), down (1), pull (2), retreat (3); slow enough
# that the head drags the toy instead of tipping it over.
_SWEEP = [(150, 0, True), (100, 1, True), (30, 1, True), (250, 2, True), (30, 2, True),
          (60, 3, True), (30, 3, True)]
# Move: the same with the closed gripper and a slower sweep (1.6 s), a push rather than a blow.
_MOVE = _SWEEP[:3] + [(400, 2, True)] + _SWEEP[4:]
TEMPLATES = {
    "lift": _template(_LIFT), "move": _template(_MOVE), "pull": _template(_DRAG),
    "push": _template(_DRAG), "rake": _template(_SWEEP), "take": _template(_LIFT),
    "pour": _template(_TILT), "slide": _template(_TILT), "unobstruct": _template(_DRAG),
}
TPL_STEPS = np.asarray([TEMPLATES[a].seg_steps for a in ACTIONS], np.int32)  # (9, S)
TPL_TARGET = np.asarray([TEMPLATES[a].target for a in ACTIONS], np.int32)
TPL_CLOSED = np.asarray([TEMPLATES[a].closed for a in ACTIONS], bool)
TPL_MEASURE = np.asarray([TEMPLATES[a].measure for a in ACTIONS], np.int32)
RAKE_ID = ACTIONS.index("rake")
UNOBSTRUCT_ID = ACTIONS.index("unobstruct")
# Which body a closed gripper locks onto (0 none, 1 the other object, 2 the toy); see
# simulate.run_program_locked.
GRASPS = np.asarray([{"take": 2, "move": 0, "rake": 0}.get(a, 1) for a in ACTIONS], np.int32)


class Tables(NamedTuple):
    """The templates of one version of the programs as (A, ...) tables in an action order (the
    nine's ``ACTIONS`` order; ``actions.tables``: the run's, a user's after the nine): ``steps``
    (A, S), ``target`` (A, S), ``closed`` (A, S), ``measure`` (A,) the step the goal is read at
    (v2: the first step it may be read at), ``n_steps`` the padded length of every program,
    ``hold`` the control steps v2 may wait after ``measure`` for the objects to rest; ``grasp``
    (A,) what a closed gripper locks onto (``GRASPS``' codes), ``held`` (A,) bool the rake is
    held from the start, ``reach`` (A,) bool the toy's reachability is read before and after."""

    steps: np.ndarray
    target: np.ndarray
    closed: np.ndarray
    measure: np.ndarray
    n_steps: int
    hold: int
    grasp: np.ndarray = GRASPS
    held: np.ndarray = np.asarray(ACTIONS) == "rake"
    reach: np.ndarray = np.asarray(ACTIONS) == "unobstruct"


def is_v3(cfg: ActionConfig) -> bool:
    """Programs v3 or later: v2 with plan-time rules and rake's dwell (v2 and v1 keep their plans bit for bit)."""
    return cfg.programs not in ("v1", "v2")


def is_v4(cfg: ActionConfig) -> bool:
    """Programs v4: v3 with the dwell before every descent, the held rake's slower transit
    (``actions.tables``), the grasp rules of ``bodies.PAD_MARGIN`` and ``programs.pushed_across``,
    the pads' sweep rules of ``pad_sweep`` and move's sweep over a low base
    (``sweep.step_raise``) (v3 keeps its plans bit for bit)."""
    return cfg.programs == "v4"


def tables(cfg: ActionConfig) -> Tables:
    """The nine built-ins' templates ``cfg.programs`` runs: v1 the module's ``TPL_*`` tables
    (``N_STEPS``); v2 the same segments with the final rest ``cfg.rest_hold`` steps longer, so
    that a goal read at rest (``labels.read_at_rest``) can wait up to ``rest_hold`` steps after
    ``measure``; v3 and v4 as v2 here (their dwells after the transit are the run's tables':
    ``actions.tables``).
    The run's tables, a user's actions after the nine: ``actions.tables``."""
    if cfg.programs == "v1":
        return Tables(TPL_STEPS, TPL_TARGET, TPL_CLOSED, TPL_MEASURE, N_STEPS, 0)
    steps = TPL_STEPS.copy()
    steps[:, -1] += int(cfg.rest_hold)
    return Tables(steps, TPL_TARGET, TPL_CLOSED, TPL_MEASURE, N_STEPS + int(cfg.rest_hold), int(cfg.rest_hold))


def run_steps(cfg: ActionConfig) -> np.ndarray:
    """(9,) int32: control steps simulated per action, ``TPL_MEASURE + 1`` (the program's own
    end; v2 plus the rest hold) or every action the padded length (``cfg.stop_at_program_end``
    False: ``N_STEPS``, v2 ``N_STEPS + rest_hold``)."""
    tb = tables(cfg)
    if cfg.stop_at_program_end:
        return (tb.measure + 1 + tb.hold).astype(np.int32)
    return np.full(len(ACTIONS), tb.n_steps, np.int32)


def untuned(cfg: ActionConfig = ActionConfig()) -> ActionConfig:
    """``cfg`` with the arm world as it was before issue 14's tuning: every geom pair through
    MJX's narrow phase, the pedestal and the palm colliding with both objects, every action
    run for ``N_STEPS``. Kept for
    ``benchmarks/actions.py`` (today's MJX against the tuned one) and the tests."""
    phys = dataclasses.replace(cfg.phys, arm_max_geom_pairs=-1, arm_pedestal_contacts=True,
                               arm_palm_objects="contact")
    return dataclasses.replace(cfg, phys=phys, stop_at_program_end=False)


def stored_config(cfg: ActionConfig) -> dict:
    """``cfg`` as a dataset's sidecar records it (``config.action_config``, compared on resume).

    The default IK solver (``ArmConfig.ik_solver="lbfgs"``) is recorded by the absence of
    ``ik_solver`` and ``ik_lm_steps``, as in every dataset written before the option existed,
    so that those stay valid and resumable; ``"lm"`` is recorded with its step count, so a
    dataset is never resumed with the other solver's plans.

    The programs' version (``ActionConfig.programs``) is recorded with its settings when it is
    v2; v1 is recorded by the absence of ``programs`` and of the v2 settings, exactly as every
    dataset written before issue 43, so those stay valid (and mean v1).

    The reach screen (``ArmConfig.reach_screen``, default on) is recorded only when off: it
    changes no stored field but ``ik_error`` (NaN where screened, ``reach_screen.py``), so a
    dataset written before it existed stays valid and resumable (its later chunks screened).

    ``scene.objects`` and ``scene.library`` are recorded only when set (the built-ins are
    recorded by their absence); the objects they resolve to go beside, ``config.objects``."""
    d = to_dict(cfg)
    if cfg.programs == "v1":  # as every dataset written before the option existed
        for k in ("programs",) + V2_FIELDS:
            d.pop(k)
    if cfg.arm.ik_solver == "lbfgs":
        d["arm"].pop("ik_solver")
        d["arm"].pop("ik_lm_steps")
    if cfg.arm.reach_screen:
        d["arm"].pop("reach_screen")
    for k in ("objects", "library"):  # the built-ins: as every dataset written before libraries
        if not d["scene"][k]:
            d["scene"].pop(k)
    return d
