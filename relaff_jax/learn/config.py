"""Settings of the evaluation protocol (paper section V) and the paper's Table II.

``ExperimentConfig`` is the frozen protocol (defaults are the paper's, docs/facts.md, "Evaluation protocol");
``experiment_preset`` gives the ``paper``, ``study`` and ``quick`` presets; ``check_config`` fails early
on settings that cannot give a study. ``TABLE2_ROWS`` / ``PAPER_TABLE2`` are the rows of
Table II and the paper's numbers (PCA, average bootstrap factor over n = 4..25: avg, min,
max over the nine affordances).
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from relaff_jax.constants import FAMILIES, SPACES
from relaff_jax.errors import UserError
from relaff_jax.learn.conditions import check_condition_names, check_conditions
from relaff_jax.learn.forests import ForestConfig, check_forest_config
from relaff_jax.learn.learners import check_learner, check_learner_node
from relaff_jax.learn.states import StateConfig

# Integer code of each state space in seed keys (part of every forest's seed: never change).
SPACE_CODE = {"pca": 0, "rhf": 1}

# "best" / "best after ten" are chosen on one half of the test scenes and scored on the other
# (cross-fitted, measures.py); "(in-sample oracle)" is the paper's: chosen on the scores it
# reports; "(online)" chooses per repetition by leave-one-out accuracy on the ten training
# samples, what an agent has after ten samples. Every "after ten" row is given in both readings
# (``ExperimentConfig.after_ten``): without a suffix the whole curve of the learner kept at
# n = 10; "(causal)" uses its choice only from n = 10 on (before it: an equal share of the
# candidates). The paper has no held-out, online or causal row.
ORACLE = " (in-sample oracle)"
ONLINE = " (online)"
CAUSAL = " (causal)"
AFTER_TEN = ("whole", "causal")  # readings of "best after ten" (docs/learning.md, "The paper's open choices")
DBN_REPEATS = ("same", "once")  # DBn's inputs: each repeated as DB1's (6 PCA / 30 RHF), or once
CATEGORY_LABELS = ("union", "both", "either")  # a category's training labels


def _ten_rows(fam: str) -> tuple[str, ...]:
    ten = f"{fam} best after ten"
    return tuple(t + s for t in (ten, ten + CAUSAL) for s in ("", ORACLE, ONLINE))


TABLE2_ROWS = (
    ("NB", "DB1 average", "DB1 best", "DB1 best (in-sample oracle)") + _ten_rows("DB1") + ("DBn",
     "CB1 average", "CB1 best", "CB1 best (in-sample oracle)") + _ten_rows("CB1") + ("CBn",)
)
PAPER_TABLE2 = {
    "NB": (1.0, 1.0, 1.0),
    "DB1 average": (1.356, 0.8055, 1.582),
    "DB1 best": (2.819, 0.9760, 3.657),
    "DB1 best after ten": (2.751, 0.8756, 3.657),
    "DBn": (2.357, 1.064, 3.090),
    "CB1 average": (1.548, 0.7860, 1.913),
    "CB1 best": (2.889, 0.8503, 3.701),
    "CB1 best after ten": (2.802, 0.7702, 3.752),
    "CBn": (2.895, 0.9072, 3.888),
}


def paper_row(name: str) -> tuple[float, float, float]:
    """The paper's avg/min/max of a Table II row (NaN for rows the paper has not). The paper's
    "best" rows chose in-sample: their numbers stand beside the oracle rows."""
    return PAPER_TABLE2.get(name.replace(ORACLE, "").replace(CAUSAL, ""), (float("nan"),) * 3) if name.endswith(ORACLE) or name in (
        "NB", "DB1 average", "DBn", "CB1 average", "CBn") else (float("nan"),) * 3


def after_ten_row(name: str, after_ten: str) -> str:
    """The Table II row of an "after ten" row ``name`` (its whole-curve name) in reading
    ``after_ten``; other rows are their own."""
    if "after ten" not in name or after_ten == "whole":
        return name
    i = name.index("after ten") + len("after ten")
    return name[:i] + CAUSAL + name[i:]


@dataclasses.dataclass(frozen=True)
class ExperimentConfig:
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

    def __post_init__(self):  # refused when the config is made (forest and state check themselves)
        check_experiment_node(self)

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
    # (tests/learn/test_engine.py), 4-10x faster per forest, for a ~26 s numba compile on first use
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


def check_experiment_node(cfg: ExperimentConfig) -> None:
    """Raise ``UserError`` if ``cfg`` cannot give a complete study (run when one is made)."""
    sizes = np.asarray(cfg.sizes)
    if sizes.ndim != 1 or len(sizes) == 0 or np.any(sizes < 2) or np.any(np.diff(sizes) <= 0):
        raise UserError(f"experiment.sizes must be strictly increasing integers >= 2, got {cfg.sizes}")
    if cfg.select_size not in cfg.sizes:
        raise UserError(f"experiment.select_size {cfg.select_size} ('best after ten') must be one of sizes {cfg.sizes}")
    if not any(cfg.bf_sizes[0] <= s <= cfg.bf_sizes[1] for s in cfg.sizes):
        raise UserError(f"experiment.sizes: no training size inside experiment.bf_sizes {cfg.bf_sizes}")
    if cfg.after_ten not in AFTER_TEN:
        raise UserError(f"experiment.after_ten must be one of {AFTER_TEN}, got {cfg.after_ten!r}")
    if cfg.category_labels not in CATEGORY_LABELS:
        raise UserError(f"experiment.category_labels must be one of {CATEGORY_LABELS}, got {cfg.category_labels!r}")
    if cfg.dbn_repeats not in DBN_REPEATS:
        raise UserError(f"experiment.dbn_repeats must be one of {DBN_REPEATS}, got {cfg.dbn_repeats!r}")
    if cfg.cbn_threshold not in cfg.thresholds:
        raise UserError(f"experiment.cbn_threshold {cfg.cbn_threshold} must be one of thresholds {cfg.thresholds}")
    for space in SPACES:  # built-ins or names of registered conditions (checked in check_config)
        check_condition_names(cfg.conditions(space), f"experiment.conditions_{space}")
    check_learner_node(cfg.learner, cfg.learner_params)
    if not 0.5 <= cfg.ci_level < 1 or cfg.ci_resamples < 10:
        raise UserError(f"experiment.ci_level must be in [0.5, 1) and ci_resamples >= 10, got {cfg.ci_level}, {cfg.ci_resamples}")
    if min(cfg.reps_pca, cfg.reps_rhf, cfg.test_size, cfg.source_size, cfg.corr_scenes, cfg.sizes_per_block) < 1:
        raise UserError("experiment: reps, test_size, source_size, corr_scenes and sizes_per_block must be >= 1")


# ExperimentConfig keys (dotted) that change no result: a folder made with other values holds the
# same experiment. The forest engines build bit-identical forests (tests/learn/test_engine.py), so a run
# may resume with another; the sweep never reads the analysis keys, which a folder begun before
# they existed lacks.
SPEED_ONLY = ("forest.engine",)
ANALYSIS_ONLY = ("chance_tol_scenes", "min_defined_share", "after_ten")
# fit-changing keys added after runs began whose default is what those runs did (issue 44): a
# folder without the key holds the default's experiment
ADDED_AS_BEFORE = {"dbn_repeats": "same", "category_labels": "union", "learner": "forest",
                   "learner_params": {}}


def result_differences(stored: Any, cfg: Any) -> list[str]:
    """The dotted keys at which a stored experiment config (``experiment.json``'s, a JSON tree)
    and ``cfg`` (an ``ExperimentConfig`` or its JSON tree) would make different results:
    every key but ``SPEED_ONLY``, and ``ANALYSIS_ONLY`` only where ``stored`` has it. The one
    rule ``learn.status`` and the sweep's resume check share."""
    from relaff_jax import io as rio
    from relaff_jax.config import differences, to_dict

    now = rio.jsonable(cfg if isinstance(cfg, dict) else to_dict(cfg))
    old = stored if isinstance(stored, dict) else {}
    return [k for k, was, new in differences(old, now)
            if k not in SPEED_ONLY and not (k in ANALYSIS_ONLY and was == "<absent>")
            and not (was == "<absent>" and k in ADDED_AS_BEFORE and new == ADDED_AS_BEFORE[k])]


def check_config(cfg: ExperimentConfig) -> None:
    """The node's own check, then scikit-learn's validation of the forest parameters, the
    learner imported and fitted once and the user's conditions run once on synthetic scenes
    (which need scikit-learn or the plugins, so they are not run when the node is made)."""
    check_experiment_node(cfg)
    check_forest_config(cfg.forest)
    check_learner(cfg.learner, cfg.learner_params, min(cfg.sizes))
    check_conditions(cfg)
