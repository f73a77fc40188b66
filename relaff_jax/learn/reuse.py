"""Another reading's experiment reused: refit only the conditions whose learner changed.

``relaff experiment --reuse DONOR`` (``run_experiment(..., reuse=DONOR)``): ``DONOR`` is an
experiment folder (finished or not) of the same data, seed, actions and protocol, differing
only in settings that change some conditions' learners (``CONDITION_SCOPED``: today
``dbn_repeats``, which changes DBn's and nothing else). A forest's seed is derived from (size,
the first condition of the plan with its learner) and its training set from the repetition's
draw, so a condition whose learner key (bootstrap rows, repeats), seed condition and
leave-one-out role are the same in both plans has the same forests, outcomes and accuracies
bit for bit (``signatures``). So:

* the space's prep (source predictors, categories, correlations) is the donor's, copied;
* per block, the conditions whose signature changed are fitted and the others read from the
  donor's block (``refit``); a block in which nothing changed is the donor's file, copied.

The results equal a run without ``--reuse`` (``tests/learn/test_reuse.py``; at the paper
preset, journal 2026-12-07 "The `once` reading from the `same` run's blocks").
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from relaff_jax import io as rio
from relaff_jax.config.experiment import ADDED_AS_BEFORE, ExperimentConfig
from relaff_jax.errors import UserError
from relaff_jax.learn import folder as L

# experiment keys whose readings differ in some conditions' learners only (their seeds,
# training sets and every other learner unchanged): a folder of another value can be reused
CONDITION_SCOPED = ("dbn_repeats",)


@dataclasses.dataclass(frozen=True)
class Donor:
    """An experiment folder to read unchanged conditions from: ``out`` and its protocol ``cfg``."""

    out: Path
    cfg: ExperimentConfig
    spaces: tuple[str, ...]  # the donor's spaces (only these are reused)


def open_donor(donor: str | os.PathLike, out: str | os.PathLike, meta: Mapping[str, Any],
               cfg: ExperimentConfig) -> Donor:
    """Check that ``donor`` can give ``out``'s experiment (``meta``: the ``experiment.json``
    ``out`` will hold; ``cfg`` its protocol) its unchanged conditions; a ``UserError`` naming
    the first mismatch otherwise. Reads only the donor's ``experiment.json``."""
    donor = Path(donor)
    if not L.meta(donor).is_file():
        raise UserError(f"--reuse {donor}: no {L.META}; give an experiment folder (relaff experiment --out, DIR/results)")
    if donor.resolve() == Path(out).resolve():
        raise UserError(f"--reuse {donor}: is the output folder itself; give another reading's folder")
    old = rio.read_json(L.meta(donor))
    scoped = {f"config.{k}" for k in CONDITION_SCOPED}
    diff = [d for d in L.meta_differences(old, dict(meta), cfg) if d not in scoped]
    if diff:
        raise UserError(f"--reuse {donor}: its experiment differs in {diff}; a folder can be reused only where "
                        f"nothing but {', '.join('experiment.' + k for k in CONDITION_SCOPED)} differs")
    stored = old.get("config", {})
    were = {k: stored.get(k, ADDED_AS_BEFORE.get(k)) for k in CONDITION_SCOPED}
    return Donor(donor, dataclasses.replace(cfg, **were), tuple(s for s in old.get("spaces", ()) if s in meta["spaces"]))


def signatures(plan: Sequence[tuple[int, tuple[int, ...]]], repeats: Mapping[int, int],
               loo_conditions: Sequence[int]) -> dict[int, tuple]:
    """``{condition: (learner key, seed condition, has leave-one-out forests)}`` of a plan, as
    ``blocks.block_outcomes`` builds them: equal signatures give equal outcomes."""
    from relaff_jax.learn.blocks import learner_key

    first: dict[tuple, int] = {}
    loo: dict[tuple, bool] = {}
    for c, rows in plan:
        key = learner_key(rows, repeats, c)
        first.setdefault(key, c)
        loo[key] = loo.get(key, False) or c in set(loo_conditions)
    return {c: (key, first[key], loo[key]) for c, rows in plan for key in [learner_key(rows, repeats, c)]}


def refit(plan: Sequence[tuple[int, tuple[int, ...]]], repeats: Mapping[int, int],
          donor_plan: Sequence[tuple[int, tuple[int, ...]]], donor_repeats: Mapping[int, int],
          loo_conditions: Sequence[int]) -> frozenset[int]:
    """The conditions of ``plan`` to fit when the donor's block (``donor_plan``) gives the rest:
    every condition of a learner any of whose conditions has another signature there (a
    learner is fitted whole or not at all)."""
    new, old = signatures(plan, repeats, loo_conditions), signatures(donor_plan, donor_repeats, loo_conditions)
    changed = {sig[:2] for c, sig in new.items() if old.get(c) != sig}
    return frozenset(c for c, sig in new.items() if sig[:2] in changed)
