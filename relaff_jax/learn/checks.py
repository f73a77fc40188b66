"""The experiment's checks that need scikit-learn or the user's plugins, run once before a sweep
(the config node checked its own values when it was built)."""
from __future__ import annotations

from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn.conditions import check_conditions
from relaff_jax.learn.forest.estimator import check_forest_config
from relaff_jax.learn.learners import check_learner


def check_config(cfg: ExperimentConfig) -> None:
    """scikit-learn's own validation of the forest parameters (the reference the node's declared
    constraints follow), the learner imported and fitted once and the user's conditions run
    once on synthetic scenes."""
    check_forest_config(cfg.forest)
    check_learner(cfg.learner, cfg.learner_params, min(cfg.sizes))
    check_conditions(cfg)
