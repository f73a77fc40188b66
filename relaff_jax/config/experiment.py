"""The experiment's settings (the tree's ``experiment`` node): ``ExperimentConfig`` (the paper's
protocol, section V), ``ForestConfig`` (the forests of III-B) and ``StateConfig`` (derived or
partial states) nested inside; ``experiment_preset`` and the keys a resume may differ in."""
from __future__ import annotations

import dataclasses
import numbers
import re
from collections.abc import Mapping
from typing import Any

from relaff_jax.config.constraints import (FRACTION, NULL, AnyOf, Boolean, Check, Interval, Options, Rule, Seq,
                                           count)
from relaff_jax.config.node import Node
from relaff_jax.constants import FAMILIES
from relaff_jax.errors import UserError
from relaff_jax import io as rio
from relaff_jax.config.override import differences, to_dict

# the forest builders (ForestConfig.engine)
ENGINES = ("fast", "sklearn", "compiled")
# readings of "each tree uses 2/3 of the samples" (ForestConfig.per_tree; docs/learning.md)
PER_TREE = ("bootstrap", "subsample")
CRITERIA = ("gini", "entropy", "log_loss")
AFTER_TEN = ("whole", "causal")  # readings of "best after ten" (docs/learning.md, "The paper's open choices")
DBN_REPEATS = ("same", "once")  # DBn's inputs: each repeated as DB1's (6 PCA / 30 RHF), or once
CATEGORY_LABELS = ("union", "both", "either")  # a category's training labels
FOREST = "forest"  # ExperimentConfig.learner of the paper's random forest
RHF_PARTS = ("dx", "dy", "dz", "dist", "angle_na_nb", "angle_na_d")  # config.perception.RHF_NAMES
EXTRAS = {"relative": 4, "reach": 2}  # derived columns: how many each adds
CONDITION_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")  # a user condition's name (learn.conditions)
MAX_SAMPLES_FRACTION = 10.0


def _real_not_int(lo: float, hi: float | None, closed: str) -> Check:
    iv = Interval(float, lo, hi, closed=closed)
    return Check(lambda v: isinstance(v, numbers.Real) and not isinstance(v, numbers.Integral)
                 and iv.problem(v) is None, f"a float {iv.describe()[len('a finite number '):]}")


def max_features_value(mf: str | None) -> str | int | float | None:
    """``ForestConfig.max_features`` as scikit-learn takes it: "sqrt" / "log2" / None as they
    are, a numeric string as an int (features per split) or a float (a fraction of them), so
    ``--set experiment.forest.max_features='"0.5"'`` is the fraction 0.5."""
    if mf is None or mf in ("sqrt", "log2"):
        return mf
    try:
        return int(mf)
    except (TypeError, ValueError):
        pass
    try:
        return float(mf)
    except (TypeError, ValueError):
        return mf


# scikit-learn's RandomForestClassifier._parameter_constraints, written out (finite numbers
# only; tests/config compares them with scikit-learn's own)
SKLEARN_FOREST = {
    "criterion": Options(CRITERIA),
    "max_depth": AnyOf(NULL, count(1)),
    "min_samples_leaf": AnyOf(count(1), _real_not_int(0.0, 1.0, "neither")),
    "max_features": AnyOf(Options(("sqrt", "log2", None)), count(1), _real_not_int(0.0, 1.0, "right")),
    "bootstrap": Boolean(),
    # scikit-learn takes any float > 0; capped at 10 here (draws per tree = round(f N): a huge f
    # would fail mid-sweep, out of memory)
    "max_samples": AnyOf(NULL, count(1), _real_not_int(0.0, MAX_SAMPLES_FRACTION, "right")),
}


@dataclasses.dataclass(frozen=True)
class ForestConfig(Node):
    """Random forest settings of paper section III-B (defaults are the paper's).

    ``max_samples`` is the reading of "each tree uses 2/3 of the samples": ``None`` (default)
    is Breiman's bootstrap of N draws with replacement, which leaves ~63 % distinct samples
    per tree ("about two thirds"); a float f draws max(1, floor(f N)) with replacement instead
    (f = 2/3 leaves only ~49 % distinct).
    """

    base_trees: int = 95
    samples_per_extra_tree: int = 20
    max_trees: int = 115
    criterion: str = "gini"
    max_depth: int = 200
    min_samples_leaf: int = 1
    max_features: str = "sqrt"
    bootstrap: bool = True
    max_samples: float | None = None
    # "bootstrap": N draws with replacement (Breiman's, ~63 % distinct: "2/3"); "subsample": 2/3
    # of the samples without replacement (``forests.subsample_weights``), the other reading of III-B
    per_tree: str = "bootstrap"
    # "fast": the same trees built by scikit-learn's Cython builder without the estimator and
    # evaluated in one jitted program (learn/forest/engine.py), bit-identical to "sklearn", the
    # RandomForestClassifier reference (tests/learn); "compiled": the same trees and
    # predictions from scikit-learn's builder re-expressed in numba, many forests per call
    # (learn/forest/compiled/, docs/learning.md)
    engine: str = "fast"

    _path = "experiment.forest"
    _constraints = {
        "base_trees": count(1, 100_000), "samples_per_extra_tree": count(1), "max_trees": count(1, 100_000),
        **{k: c for k, c in SKLEARN_FOREST.items() if k != "max_features"},
        "max_features": Check(lambda v: SKLEARN_FOREST["max_features"].problem(max_features_value(v)) is None,
                              SKLEARN_FOREST["max_features"].describe() + " (a number as a quoted string)"),
        "per_tree": Options(PER_TREE),
        "engine": Options(ENGINES),
        ("criterion", "engine"): Rule(
            lambda c: c.engine == "sklearn" or c.criterion == "gini",
            lambda c: f"{c.criterion!r}: the {c.engine} engine builds gini trees only (the paper's); set "
                      "experiment.forest.engine=sklearn for another criterion"),
        ("max_samples", "bootstrap"): Rule(lambda c: c.bootstrap or c.max_samples is None,
                                           lambda c: "needs experiment.forest.bootstrap=true"),
    }


@dataclasses.dataclass(frozen=True)
class StateConfig(Node):
    """What a state holds beyond (or instead of) the paper's; the defaults are the paper's.

    extra: derived columns appended in both spaces, from the canonical PCA centroids (robot
        frame, robot at the origin): ``"relative"`` = toy minus other object dx, dy, dz and
        their planar distance (4); ``"reach"`` = each object's planar distance from the robot,
        toy then other (2). A forest that needs these as oblique functions of x, y gets them
        as one column.
    rhf_pca: RHF space keeps the 18 PCA values (the paper's 318) or holds the bins alone.
    rhf_parts: the RHF sub-histograms kept (``RHF_PARTS``, 50 bins each), in their order.
    """

    extra: tuple[str, ...] = ()
    rhf_pca: bool = True
    rhf_parts: tuple[str, ...] = RHF_PARTS

    _path = "experiment.state"
    _constraints = {"extra": Seq(Options(EXTRAS), min_len=0, distinct=True), "rhf_pca": Boolean(),
                    "rhf_parts": Seq(Options(RHF_PARTS), distinct=True)}


def _conditions() -> Check:
    return Check(lambda v: isinstance(v, (tuple, list)) and "NB" in v and len(set(v)) == len(v)
                 and all(n in FAMILIES or (isinstance(n, str) and CONDITION_NAME.match(n)) for n in v),
                 f"a list naming NB and each condition once, built-in {FAMILIES} or a registered name")


def _pair() -> Seq:
    return Seq(count(1, 1_000_000), length=2)


def _ordered(key: str) -> Rule:
    return Rule(lambda c: getattr(c, key)[0] <= getattr(c, key)[1],
                lambda c: f"must be [lo, hi] with lo <= hi, got {list(getattr(c, key))}")


def _learner_params_ok(c: Any) -> bool:
    return not (c.learner == FOREST and c.learner_params) and "random_state" not in c.learner_params


@dataclasses.dataclass(frozen=True)
class ExperimentConfig(Node):
    """Protocol settings; defaults are the paper's (section V, docs/facts.md, "Evaluation protocol")."""

    sizes: tuple[int, ...] = tuple(range(2, 101))  # training sizes n
    reps_pca: int = 50
    reps_rhf: int = 25
    test_size: int = 4000
    source_size: int = 2000  # samples per source predictor (and per half of a category)
    corr_scenes: int = 500  # held-out scenes per action shown to all nine predictors
    shrink_to_data: bool = False  # quick preset: shrink source/corr/test sizes to small datasets
    repeats_pca: int = 6  # bootstrap input repetitions (24-dim PCA state with one input)
    repeats_rhf: int = 30  # (348-dim RHF state with one input)
    # DBn's eight inputs: "same" repeats each as often as DB1's one (66 PCA columns), "once"
    # adds each once (26): the paper states the repetition for DB1 and CB1 only (learning.md)
    dbn_repeats: str = "same"
    # a category's training labels on the union of its two source sets: "union" each scene its
    # own action's label; "both" / "either": positive where both / either affordance holds (the
    # other's label predicted by its source predictor: the datasets hold one action each)
    category_labels: str = "union"
    thresholds: tuple[float, ...] = (0.0, 0.125, 0.5)  # correlation heuristic, paper V-F
    cbn_threshold: float = 0.5  # categories used by CBn in Table II (paper V-G)
    categories_with_target: bool = False  # may a category built from the target itself be used?
    conditions_pca: tuple[str, ...] = FAMILIES
    conditions_rhf: tuple[str, ...] = ("NB", "DB1")  # the paper shows only NB and DB1 in RHF
    bf_sizes: tuple[int, int] = (4, 25)  # average bootstrap factor interval (paper V-C)
    best_sizes: tuple[int, int] = (2, 100)  # "best" = highest mean accuracy over these n
    select_size: int = 10  # "best after ten" (offline: mean test accuracy; online: leave-one-out)
    # which "after ten" rows the findings use: "whole" (the whole curve of the learner kept at
    # select_size) or "causal" (nothing chosen before it); both are always computed and shown
    after_ten: str = "whole"
    online_select: bool = True  # fit the leave-one-out forests of the online choice (off: its rows are NaN)
    chance: float = 0.5
    # test and training draws (draws.py): one test set per target, balanced by class; the
    # training draws at random from what is left (the paper's reading) or alternating classes
    balanced_test: bool = True
    balanced_train: bool = False
    # per test scene outcomes, kept for intervals over test scenes too and for the held-out
    # "best" rows and the threshold study (bit-packed on disk; the paper preset sets it)
    keep_outcomes: bool = False
    ci_level: float = 0.95  # bootstrap intervals (intervals.py)
    ci_resamples: int = 1000
    # a bias-corrected end must leave at least this share of the resamples beyond it, else the
    # interval is the percentile one (intervals.checked_interval; 0: bias-corrected everywhere)
    ci_tail: float = 0.005
    # bf is undefined where P_sl - P_c <= this many test scenes' worth (k / T): |bf| <= T / (2 k)
    chance_tol_scenes: float = 0.5
    # a target enters a bf row only with bf defined at >= this share of the window's sizes
    min_defined_share: float = 0.5
    sizes_per_block: int = 25
    forest: ForestConfig = ForestConfig()
    # derived or partial states (relative and reach columns, RHF bins only, named RHF parts)
    # for finding what a learner relies on; the default is the paper's PCA and RHF states
    state: StateConfig = StateConfig()
    # the classifier of every forest above (learners.py): "forest" (the paper's, ForestConfig) or
    # a scikit-learn classifier's import path, with its constructor's keyword arguments
    learner: str = "forest"
    learner_params: dict = dataclasses.field(default_factory=dict)

    _path = "experiment"
    _constraints = {
        "sizes": Seq(count(2, 1_000_000), increasing=True),
        "reps_pca": count(1, 100_000), "reps_rhf": count(1, 100_000),
        "test_size": count(1, 100_000_000), "source_size": count(1, 100_000_000),
        "corr_scenes": count(1, 100_000_000), "shrink_to_data": Boolean(),
        "repeats_pca": count(1, 10_000), "repeats_rhf": count(1, 10_000),
        "dbn_repeats": Options(DBN_REPEATS), "category_labels": Options(CATEGORY_LABELS),
        "thresholds": Seq(Interval(float, -1.0, 1.0)), "cbn_threshold": Interval(float, -1.0, 1.0),
        "categories_with_target": Boolean(),
        "conditions_pca": _conditions(), "conditions_rhf": _conditions(),
        "bf_sizes": _pair(), "best_sizes": _pair(), "select_size": count(2, 1_000_000),
        "after_ten": Options(AFTER_TEN), "online_select": Boolean(),
        "chance": Interval(float, 0.0, 1.0, closed="neither"),
        "balanced_test": Boolean(), "balanced_train": Boolean(), "keep_outcomes": Boolean(),
        "ci_level": Interval(float, 0.5, 1.0, closed="left"), "ci_resamples": count(10, 10_000_000),
        "ci_tail": Interval(float, 0.0, 0.5),
        "chance_tol_scenes": Interval(float, 0.0, 1e6), "min_defined_share": FRACTION,
        "sizes_per_block": count(1, 1_000_000),
        "learner": Check(lambda v: isinstance(v, str) and v != "", "'forest' or an import path"),
        "learner_params": Check(lambda v: isinstance(v, Mapping) and all(isinstance(k, str) for k in v),
                                "a JSON object of keyword arguments"),
        ("bf_sizes",): _ordered("bf_sizes"), ("best_sizes",): _ordered("best_sizes"),
        ("select_size", "sizes"): Rule(lambda c: c.select_size in c.sizes,
                                       lambda c: f"({c.select_size}, 'best after ten') must be one of sizes {list(c.sizes)}"),
        ("sizes", "bf_sizes"): Rule(lambda c: any(c.bf_sizes[0] <= s <= c.bf_sizes[1] for s in c.sizes),
                                    lambda c: f"has no training size inside experiment.bf_sizes {list(c.bf_sizes)}"),
        ("ci_tail", "ci_level"): Rule(lambda c: c.ci_tail <= (1 - c.ci_level) / 2,
                                      lambda c: f"({c.ci_tail}) must be at most (1 - experiment.ci_level) / 2 = "
                                      f"{(1 - c.ci_level) / 2:g}: the share the percentile interval leaves beyond each end"),
        ("cbn_threshold", "thresholds"): Rule(lambda c: c.cbn_threshold in c.thresholds,
                                              lambda c: f"({c.cbn_threshold}) must be one of thresholds {list(c.thresholds)}"),
        ("learner_params", "learner"): Rule(
            _learner_params_ok,
            lambda c: "random_state: each fit's random_state is derived from the run's seed (--seed); leave it out"
            if "random_state" in c.learner_params else "are for a scikit-learn learner; the paper's forest takes "
            "its settings from experiment.forest.*"),
    }

    def reps(self, space: str) -> int:
        return self.reps_pca if space == "pca" else self.reps_rhf

    def repeats(self, space: str) -> int:
        return self.repeats_pca if space == "pca" else self.repeats_rhf

    def dbn_repeat(self, space: str) -> int:
        """How often each of DBn's inputs is repeated in ``space``."""
        return self.repeats(space) if self.dbn_repeats == "same" else 1

    def conditions(self, space: str) -> tuple[str, ...]:
        return self.conditions_pca if space == "pca" else self.conditions_rhf


WINDOW = tuple(range(4, 26))  # the paper's window of the average bootstrap factor, n = 4..25


def experiment_preset(name: str) -> ExperimentConfig:
    """``paper``: the full protocol, forests built by the compiled engine. ``quick``: every
    condition at n = 2 and every n of the window 4..25, 2 repetitions, shrunk to small
    datasets, outcomes per test scene kept.
    ``study``: every n from 2 to 50, 10 repetitions, 500 balanced test scenes per action
    and 300 source + 100 correlation scenes: 1,000 samples per action leave 100 training scenes;
    the compiled engine, like ``paper``. ``quick`` keeps the default ``fast`` engine, whose
    forests are the same, and so does every preset built on it."""
    # the long presets build their forests with the compiled engine: the same forests
    # (tests/learn), 4-10x faster per forest, for a ~26 s numba compile on first use
    compiled = ForestConfig(engine="compiled")
    if name == "paper":  # without the outcomes the held-out "best" rows and the threshold study are not measurable
        return ExperimentConfig(keep_outcomes=True, forest=compiled)
    if name == "quick":
        return ExperimentConfig(
            sizes=(2,) + WINDOW, reps_pca=2, reps_rhf=2, test_size=2000, shrink_to_data=True, keep_outcomes=True,
        )
    if name == "study":
        return ExperimentConfig(
            sizes=tuple(range(2, 51)), reps_pca=10, reps_rhf=10, test_size=500, source_size=300, corr_scenes=100,
            keep_outcomes=True, forest=compiled,
        )
    raise UserError(f"unknown preset {name!r}; expected 'quick', 'study' or 'paper'")


# ExperimentConfig keys (dotted) that change no result: a folder made with other values holds the
# same experiment. The forest engines build bit-identical forests (tests/learn), so a run
# may resume with another; the sweep never reads the analysis keys, which a folder begun before
# they existed lacks.
SPEED_ONLY = ("forest.engine",)
ANALYSIS_ONLY = ("chance_tol_scenes", "min_defined_share", "after_ten", "ci_tail")
# fit-changing keys added after runs began whose default is what those runs did (issue 44): a
# folder without the key holds the default's experiment
ADDED_AS_BEFORE = {"dbn_repeats": "same", "category_labels": "union", "learner": "forest",
                   "learner_params": {}}


def result_differences(stored: Any, cfg: Any) -> list[str]:
    """The dotted keys at which a stored experiment config (``experiment.json``'s, a JSON tree)
    and ``cfg`` (an ``ExperimentConfig`` or its JSON tree) would make different results:
    every key but ``SPEED_ONLY``, and ``ANALYSIS_ONLY`` only where ``stored`` has it. The one
    rule ``learn.status`` and the sweep's resume check share."""
    now = rio.jsonable(cfg if isinstance(cfg, dict) else to_dict(cfg))
    old = stored if isinstance(stored, dict) else {}
    return [k for k, was, new in differences(old, now)
            if k not in SPEED_ONLY and not (k in ANALYSIS_ONLY and was == "<absent>")
            and not (was == "<absent>" and k in ADDED_AS_BEFORE and new == ADDED_AS_BEFORE[k])]
