"""The run's templates as tables: every registered action's (``registry()``: the nine, then a
user's), what the compiled programs index with the traced action id.

``tables(cfg) -> templates.Tables`` (A, ...) and ``run_steps(cfg) -> (A,)``; for the nine
built-ins they are ``templates.TPL_*``, ``GRASPS`` (v1) and v2's longer rest, row for row, with
v3's dwell in rake and v4's before every built-in's descent (``dwells``).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.sim.templates import N_SEGMENTS, N_STEPS, ActionConfig, Tables, _template, is_v3, is_v4

from .registry import is_builtin, registry
from .spec import GRASP_CODE


def spec_tables(specs, dwell: dict[str, int] | None = None, transit: dict[str, int] | None = None) -> Tables:
    """v1's tables of ``specs`` (checked ``ActionSpec``s): each template padded by
    ``templates._template``, its measuring step the spec's (default: the end of its segments).
    ``dwell``: steps each built-in it names holds its first waypoint after its transit (a segment
    inserted after the first, its measuring step as much later; ``dwells``); ``transit``: the
    length of the first segment (the transit from home) of each built-in it names, instead of
    the template's (``transits``). The padding is ``N_SEGMENTS`` segments and ``N_STEPS`` steps,
    or more where a dwell or a transit needs them."""
    rows = [_dwelled(_transit(s, (transit or {}).get(s.name, 0)) if is_builtin(s.name) else s,
                     (dwell or {}).get(s.name, 0) if is_builtin(s.name) else 0) for s in specs]
    n_seg = max([N_SEGMENTS] + [len(seg) for seg, _ in rows])
    n_steps = max([N_STEPS] + [sum(g[0] for g in seg) + n_seg - len(seg) for seg, _ in rows])
    tpl = [_template(seg, n_seg, n_steps) for seg, _ in rows]
    measure = [t.measure if m is None else m for (_, m), t in zip(rows, tpl)]
    return Tables(np.asarray([t.seg_steps for t in tpl], np.int32), np.asarray([t.target for t in tpl], np.int32),
                  np.asarray([t.closed for t in tpl], bool), np.asarray(measure, np.int32), n_steps, 0,
                  np.asarray([GRASP_CODE[s.grasp] for s in specs], np.int32),
                  np.asarray([s.grasp == "tool" for s in specs], bool), np.asarray([s.reach for s in specs], bool))


def _transit(spec, n: int):
    """A spec whose first segment (the transit from home) lasts ``n`` steps (as declared for 0),
    its measuring step as much later or earlier."""
    seg = tuple(spec.segments)
    if n <= 0 or n == seg[0][0]:
        return spec
    measure = None if spec.measure is None else spec.measure + n - seg[0][0]
    return dataclasses.replace(spec, segments=((n,) + tuple(seg[0][1:]),) + seg[1:], measure=measure)


def _dwelled(spec, n: int) -> tuple[tuple, int | None]:
    """A spec's segments with its first waypoint held ``n`` steps after the first segment (none
    for 0) and its measuring step (``None``: the end of its segments)."""
    seg = tuple(spec.segments)
    if n <= 0:
        return seg, spec.measure
    return seg[:1] + ((n, seg[0][1], seg[0][2]),) + seg[1:], None if spec.measure is None else spec.measure + n


# v3: control steps the held rake holds its first waypoint (``above``, over the toy) after the
# transit from home, before the descent. The transit interpolates the joints in 150 steps
# (0.6 s); the position servos lag a large base turn (at its end the hand was 0.3-1.7 m short
# of ``above`` for base turns of 105-170 degrees, C replays, journal), so v2's descent began
# wherever the hand was and cut the corner down onto the toy. RAKE_DWELL lets the hand arrive.
RAKE_DWELL = 150


# v4: control steps every other built-in program holds its first waypoint (the pose above the
# objects, before the descent to the grasp or to the table) after the transit from home. The
# transit interpolates the joints in 150 steps; at its end the servos still lag a large swing
# (joint errors up to ~20 degrees, the tcp up to ~0.5 m from the waypoint) and overshoot it
# before they settle, and v3's descent began wherever the hand was (pull 335 of the paper v3
# dataset: a finger met a cup's rim, then the pad pressed the ball in it at 70 N). After 150 steps
# (0.6 s, rake's dwell too) the tcp is within 0.5 mm of the waypoint in C replays of v4 programs
# (docs/actions.md, "Programs v4").
DESCENT_DWELL = 150


# v4: control steps of the held rake's transit from home to its first waypoint (``above``, the tool
# 10 cm over the toy), instead of the template's 150. At 150 the servos lag the arm's swing with
# the tool and overshoot ``above`` early in the dwell: in C replays of 302 v3 programs of the paper
# dataset the tool touched the toy in 27, at steps 181-199, up to 10.6 mm deep (rake 40271: 39 N
# held). With 300 steps no tool came within 73 mm of the toy in 124 replays of the same plans
# (docs/actions.md, "Programs v4").
TOOL_TRANSIT = 300


def transits(cfg: ActionConfig) -> dict[str, int]:
    """The transit's length each built-in runs under ``cfg.programs`` where it is not its
    template's: v4's held rake ``TOOL_TRANSIT``; none before v4."""
    return {"rake": TOOL_TRANSIT} if is_v4(cfg) else {}


def dwells(cfg: ActionConfig) -> dict[str, int]:
    """The steps each built-in holds its first waypoint after the transit under ``cfg.programs``:
    none (v1, v2), rake's ``RAKE_DWELL`` (v3), and v4 the others' ``DESCENT_DWELL`` too."""
    if not is_v3(cfg):
        return {}
    if not is_v4(cfg):
        return {"rake": RAKE_DWELL}
    return {a: RAKE_DWELL if a == "rake" else DESCENT_DWELL for a in ACTIONS}


def tables(cfg: ActionConfig) -> Tables:
    """The templates ``cfg.programs`` runs for the run's actions: v1 as declared (``N_STEPS``);
    v2 the same segments with the final rest ``cfg.rest_hold`` steps longer, so that a goal read
    at rest (``labels.read_at_rest``) can wait up to ``rest_hold`` steps after ``measure``; v3
    as v2 with rake's dwell after the transit, v4 with every built-in's (``dwells``)."""
    tb = spec_tables(registry(), dwells(cfg), transits(cfg))
    if cfg.programs == "v1":
        return tb
    steps = tb.steps.copy()
    steps[:, -1] += int(cfg.rest_hold)
    return tb._replace(steps=steps, n_steps=tb.n_steps + int(cfg.rest_hold), hold=int(cfg.rest_hold))


def run_steps(cfg: ActionConfig) -> np.ndarray:
    """(A,) int32: control steps simulated per action, ``measure + 1`` (the program's own
    end; v2 plus the rest hold) or every action the padded length (``cfg.stop_at_program_end``
    False: ``N_STEPS``, v2 ``N_STEPS + rest_hold``)."""
    tb = tables(cfg)
    if cfg.stop_at_program_end:
        return (tb.measure + 1 + tb.hold).astype(np.int32)
    return np.full(len(tb.measure), tb.n_steps, np.int32)
