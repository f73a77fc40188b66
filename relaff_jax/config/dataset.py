"""The dataset's settings (the tree's ``dataset`` node): how many samples, batch sizes, the
rollout cap, negative matching."""
from __future__ import annotations

import dataclasses

from relaff_jax.config.constraints import FRACTION, Interval, Options, count
from relaff_jax.config.node import Node
from relaff_jax.constants import SIM_ENGINES

POPULATIONS = ("all", "feasible")  # which rollouts may be selected (data.selection)
NEGATIVES = ("cog", "uniform")  # how negatives are drawn
UNSETTLED = ("refuse", "keep")  # a rollout whose objects never came to rest: no label, or its last step's


@dataclasses.dataclass(frozen=True)
class DatasetConfig(Node):
    """Every dataset setting: how many samples, batch sizes, the rollout cap, negative matching.

    n_samples: balanced samples per action (N/2 positives, N/2 distance-matched negatives).
    rollout_batch: rollouts simulated per chunk (one ``rollout_fn`` call, one compile).
    feature_batch: samples per feature chunk (one perception call).
        ``generate_dataset`` reads ``n_samples`` and ``rollout_batch`` from this node (their one
        source); ``add_features`` takes its batch as an argument (its callers pass ``feature_batch``).
    max_rollouts: cap on simulated rollouts (rounded up to whole chunks); the paper's
        1.5M simulations over nine actions are ~170k per action. Not part of the resume
        check, so a run stopped by the cap can be rerun with a larger one.
    distance_bins: equal-width COG-distance bins spanning the selected positives' range.
    engine: executor of the motor programs, ``constants.SIM_ENGINES`` ("mjx" or "native");
        recorded in the sidecar, and resuming a dataset with another engine is refused.
    borrow_fraction: generation stops once at most this fraction of the negatives has to be
        borrowed from outside its distance bin (0 = exact histogram match). At the cap, or
        after ``match_patience``, any amount is accepted, with a warning, and the number and
        ``matching_met`` are recorded.
    population: which rollouts may be selected, ``POPULATIONS``: ``"all"`` (the
        paper's reading: an infeasible program is a negative) or ``"feasible"`` (only
        rollouts whose motor program was executable; the rollouts need a ``feasible`` field).
    negatives: ``NEGATIVES``: ``"cog"`` (matched on the centres' distance, the
        paper's) or ``"uniform"``.
    match_patience: once a balanced selection first exists at k chunks, simulate at most
        ``ceil(match_patience * k)`` chunks for the distance matching to be met, then accept
        the borrowing (recorded, warned). With the population "feasible" the matched
        negatives are feasible stacked pairs that fail, which may be rare: without this the
        generator would run to the cap.
    unsettled: ``UNSETTLED``: ``"refuse"`` (a rollout whose objects were still moving when the
        bounded rest hold ended, ``settled`` False, has no outcome to read: it is never
        selected, and the refusals are counted) or ``"keep"`` (its goal read at the hold's
        last step, as datasets made before this setting). A program not executed counts as
        settled; rollouts without a ``settled`` field (a rollout function with no rest read)
        are all taken, and ``unsettled_refused`` is recorded as null.
    """

    max_rollouts: int = 200_000
    distance_bins: int = 20
    borrow_fraction: float = 0.01
    n_samples: int = 10_000
    rollout_batch: int = 256
    feature_batch: int = 32
    engine: str = "mjx"
    population: str = "all"
    negatives: str = "cog"
    match_patience: float = 4.0
    unsettled: str = "refuse"

    _path = "dataset"
    _constraints = {
        "max_rollouts": count(1, 10**15), "distance_bins": count(1, 100_000),
        "borrow_fraction": FRACTION, "n_samples": count(2, 10**15),  # past the rollout cap: sample_bound says so, with the time
        "rollout_batch": count(1, 1 << 20), "feature_batch": count(1, 1 << 16),
        "engine": Options(SIM_ENGINES), "population": Options(POPULATIONS), "negatives": Options(NEGATIVES),
        "match_patience": Interval(float, 1.0, 1e6), "unsettled": Options(UNSETTLED),
    }
