"""Learning: the paper's random forests, the bootstrapping protocol, sweeps and their analysis.

Takes one featured dataset per action (``load_datasets(DIRS)``, or ``synthetic_datasets``)
and gives, per state space, the accuracies of every bootstrapping condition on disk
(``run_experiment``), from which ``analyse`` computes bootstrap factors and Table II.

Files, in pipeline order:

- ``forest/``: the paper's forests and the engines that build them (``forest/__init__.py``):
  ``estimator.py`` (``ForestConfig``'s forests as scikit-learn estimators: ``n_trees``,
  ``make_forest``, ``fit_forest``, ``predict_class``), ``fit.py`` (the same trees from
  scikit-learn's Cython builder directly), ``evaluate.py`` (their exact predictions, many forests
  in one jitted program), ``compiled/`` (trees and predictions in numba), ``engine.py`` (the
  engine the sweep and prep use: ``ForestConfig.engine``: fast | compiled | sklearn);
- ``learners.py``: the learner of every forest: the paper's (default) or a scikit-learn classifier
  by import path (``ExperimentConfig.learner``, ``learner_params``);
- ``conditions.py``: conditions as registered functions (``register_condition``, ``Knowledge``),
  the paper's five as built-ins, a user's from ``--plugins FILE.py`` or entry points;
- ``states.py``: ``state_features`` (manipulated object first), ``augment`` (bootstrap inputs);
- ``correlation.py``: the categories and the correlation heuristic;
- ``synthetic.py``: synthetic datasets in ``load_dataset``'s layout (``--synthetic``, tests);
- ``synthetic_results.py``: a synthetic experiment folder in the sweep's layout (report tests,
  ``benchmarks/report_stage.py``);
- ``table2.py``: Table II's rows and the paper's numbers; ``checks.py``: ``check_config`` (the
  checks that need scikit-learn or plugins); the settings are ``relaff_jax.config.experiment``;
- ``protocol.py``: condition axis and plans, pools, ``forests_per_space``;
- ``draws.py``: each target's (balanced) test set and each repetition's training order;
- ``datasets.py``: loading, checking and fingerprinting the input datasets;
- ``prep.py``: source predictors, categories and the correlation matrix of one space;
- ``blocks.py``: one (target, repetition, sizes) block of the sweep (accuracies, outcomes per
  test scene, leave-one-out accuracy at ``select_size``), saved and re-read;
- ``parallel.py``: forest jobs over worker processes with a progress bar;
- ``sweep.py``: ``run_experiment``, the resumable sweep of one or both spaces;
- ``folder.py``: the experiment folder's file names (``experiment.json``, ``SPACE/results.npz``, ...);
- ``results.py``: ``load_results`` (typed ``Results`` / ``SpaceResults``), ``is_complete``;
- ``measures.py``: Table II rows (average bf with its defined sizes, accuracy gain), ties;
- ``online.py``: the online "best after ten" (leave-one-out choice per repetition);
- ``intervals.py``: bootstrap resamples over repetitions and test scenes, percentile intervals;
- ``analysis.py``: curves, bootstrap factors, Table II with intervals, the threshold study.

The stage over the whole config tree (what ``relaff experiment`` and ``relaff reproduce`` call,
with the folder's config record) is ``relaff_jax.stages.experiment``. Nothing here imports the
report, the stages or the command line.
"""
from __future__ import annotations

from relaff_jax.constants import (
    ACTIONS,
    FAMILIES,
    SPACES,
)
from relaff_jax.learn.analysis import (analyse, average_bf, categories_per_threshold, curves, select_at, select_best,
                                       threshold_study)
from relaff_jax.learn.checks import check_config
from relaff_jax.learn.conditions import (Knowledge, load_plugin_file, register_condition, registered as registered_conditions)
from relaff_jax.learn.correlation import categories_above, category_pairs, correlation_matrix
from relaff_jax.learn.datasets import check_datasets, fingerprint, load_datasets
from relaff_jax.learn.draws import draw_rep, draw_test, draw_train
from relaff_jax.learn.forest.estimator import check_forest_config, fit_forest, make_forest, n_trees, predict_class
from relaff_jax.learn.intervals import bc_interval, checked_interval, half_sizes, percentile_interval, resampled_means, scene_halves, whole
from relaff_jax.learn.measures import (bootstrap_factor, chance_tolerance, min_defined, size_mask, summarise,
                                       table2_rows, tie_weights, window_mean)
from relaff_jax.learn.online import extend, online_weights
from relaff_jax.learn.prep import prepare
from relaff_jax.learn.protocol import (block_fits, category_allowed, category_masks, condition_names, condition_plan,
                                       forests_per_space, layout, pool_sizes, split_pools)
from relaff_jax.learn.states import TOY_MANIPULATED, augment, check_action, manipulated_first_order, state_features
from relaff_jax.learn.synthetic import synthetic_datasets
from relaff_jax.learn.table2 import PAPER_TABLE2, TABLE2_ROWS, ORACLE, paper_row

# Not re-exported: the modules that import scikit-learn or JAX (``blocks``: ``run_block``,
# ``read_block``; ``results``: ``load_results``, ``is_complete``, ``Results``; ``sweep``:
# ``run_experiment``), so that ``relaff reproduce --status``, which reads ``learn.status``,
# imports neither. Import those names from their modules.

__all__ = [
    "ACTIONS", "FAMILIES", "SPACES", "PAPER_TABLE2", "TABLE2_ROWS", "TOY_MANIPULATED", "Knowledge",
    "analyse", "augment", "average_bf", "block_fits", "bootstrap_factor", "categories_above", "categories_per_threshold",
    "category_allowed", "category_masks", "category_pairs", "check_action", "check_config", "check_datasets",
    "check_forest_config", "condition_names", "condition_plan", "correlation_matrix", "curves", "draw_rep", "fingerprint", "fit_forest", "forests_per_space", "layout", "load_datasets", "make_forest", "manipulated_first_order", "n_trees", "predict_class", "prepare", "select_at", "select_best", "size_mask",
    "split_pools", "state_features", "synthetic_datasets", "threshold_study", "draw_test", "draw_train", "extend", "online_weights", "paper_row", "percentile_interval",
    "resampled_means", "summarise", "register_condition", "registered_conditions", "load_plugin_file", "pool_sizes", "bc_interval", "checked_interval", "half_sizes", "scene_halves", "whole", "chance_tolerance", "min_defined", "ORACLE", "table2_rows", "tie_weights", "window_mean",
]
