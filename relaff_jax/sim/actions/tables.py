"""The run's templates as tables: every registered action's (``registry()``: the nine, then a
user's), what the compiled programs index with the traced action id.

``tables(cfg) -> templates.Tables`` (A, ...) and ``run_steps(cfg) -> (A,)``; for the nine
built-ins they are ``templates.TPL_*``, ``GRASPS`` (v1) and v2's longer rest, row for row.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from relaff_jax.sim.templates import N_STEPS, ActionConfig, Tables, _template, is_v3

from .registry import registry
from .spec import GRASP_CODE


def spec_tables(specs) -> Tables:
    """v1's tables of ``specs`` (checked ``ActionSpec``s): each template padded by
    ``templates._template``, its measuring step the spec's (default: the end of its segments)."""
    tpl = [_template(s.segments) for s in specs]
    measure = [t.measure if s.measure is None else s.measure for s, t in zip(specs, tpl)]
    return Tables(np.asarray([t.seg_steps for t in tpl], np.int32), np.asarray([t.target for t in tpl], np.int32),
                  np.asarray([t.closed for t in tpl], bool), np.asarray(measure, np.int32), N_STEPS, 0,
                  np.asarray([GRASP_CODE[s.grasp] for s in specs], np.int32),
                  np.asarray([s.grasp == "tool" for s in specs], bool), np.asarray([s.reach for s in specs], bool))


# v3: control steps the held rake holds its first waypoint (``above``, over the toy) after the
# transit from home, before the descent. The transit interpolates the joints in 150 steps
# (0.6 s); the position servos lag a large base turn (at its end the hand was 0.3-1.7 m short
# of ``above`` for base turns of 105-170 degrees, C replays, journal), so v2's descent began
# wherever the hand was and cut the corner down onto the toy. RAKE_DWELL lets the hand arrive.
RAKE_DWELL = 150


def with_rake_dwell(specs):
    """The specs with the built-in rake's template holding ``above`` for ``RAKE_DWELL`` steps after
    its transit (its measuring step ``RAKE_DWELL`` later); the other specs as they are."""
    def dwell(s):
        if s.name != "rake" or s.grasp != "tool":
            return s
        seg = tuple(s.segments)
        first = seg[0]
        return dataclasses.replace(s, segments=seg[:1] + ((RAKE_DWELL, first[1], first[2]),) + seg[1:],
                                   measure=None if s.measure is None else s.measure + RAKE_DWELL)
    return tuple(dwell(s) for s in specs)


def tables(cfg: ActionConfig) -> Tables:
    """The templates ``cfg.programs`` runs for the run's actions: v1 as declared (``N_STEPS``);
    v2 the same segments with the final rest ``cfg.rest_hold`` steps longer, so that a goal read
    at rest (``labels.read_at_rest``) can wait up to ``rest_hold`` steps after ``measure``; v3
    as v2 with rake's dwell after the transit (``with_rake_dwell``)."""
    specs = registry()
    tb = spec_tables(with_rake_dwell(specs) if is_v3(cfg) else specs)
    if cfg.programs == "v1":
        return tb
    steps = tb.steps.copy()
    steps[:, -1] += int(cfg.rest_hold)
    return tb._replace(steps=steps, n_steps=N_STEPS + int(cfg.rest_hold), hold=int(cfg.rest_hold))


def run_steps(cfg: ActionConfig) -> np.ndarray:
    """(A,) int32: control steps simulated per action, ``measure + 1`` (the program's own
    end; v2 plus the rest hold) or every action the padded length (``cfg.stop_at_program_end``
    False: ``N_STEPS``, v2 ``N_STEPS + rest_hold``)."""
    tb = tables(cfg)
    if cfg.stop_at_program_end:
        return (tb.measure + 1 + tb.hold).astype(np.int32)
    return np.full(len(tb.measure), tb.n_steps, np.int32)
