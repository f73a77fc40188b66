"""The bootstrapping protocol as index arithmetic (paper section V): conditions, pools, draws.

Takes the actions (A of them), the config and, for the category conditions, the 9 x 9
correlation matrix of the source predictors; gives

* the condition axis of the results: ``condition_names`` / ``layout`` (NB, DB1 x A, DBn,
  CB1 x K, CBn x thresholds) and per target the ``condition_plan``, ``[(condition index,
  bootstrap rows)]``; ``category_allowed`` / ``category_masks`` say which categories a
  target may use;
* disjoint index pools of each action's dataset (``split_pools``: source, correlation
  scenes, target pool); each target's test set and training orders are ``draws.py``'s;
* forest counts: ``block_fits`` (one block of sizes) and ``forests_per_space`` (a whole
  space: source predictors, categories and every condition's forests).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from relaff_jax.sim.actions.registry import names as _action_names  # the run's actions (no JAX)
from relaff_jax.errors import UserError
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn.correlation import categories_above, category_pairs
from relaff_jax.provenance import derive_seed
from relaff_jax.config import streams


def condition_names(actions: Sequence[str], thresholds: Sequence[float]) -> list[str]:
    """Names of the condition axis: NB, DB1:<src> x A, DBn, CB1:<a>+<b> x K, CBn:T=<T> x len(T)."""
    return (
        ["NB"]
        + [f"DB1:{a}" for a in actions]
        + ["DBn"]
        + [f"CB1:{actions[i]}+{actions[j]}" for i, j in category_pairs(actions)]
        + [f"CBn:T={t:g}" for t in thresholds]
    )


def layout(n_actions: int, n_thresholds: int) -> dict[str, Any]:
    """Index ranges of each family on the condition axis."""
    k = n_actions * (n_actions - 1) // 2
    return {
        "NB": 0,
        "DB1": np.arange(1, 1 + n_actions),
        "DBn": 1 + n_actions,
        "CB1": np.arange(2 + n_actions, 2 + n_actions + k),
        "CBn": np.arange(2 + n_actions + k, 2 + n_actions + k + n_thresholds),
        "n": 2 + n_actions + k + n_thresholds,
    }


def category_allowed(actions: Sequence[str], cfg: ExperimentConfig) -> np.ndarray:
    """``(A, K)`` bool: may target t use category k? (not if built from t itself, by default)."""
    pairs = np.asarray(category_pairs(actions), dtype=int).reshape(-1, 2)
    t = np.arange(len(actions))[:, None]
    involves = (pairs[None, :, 0] == t) | (pairs[None, :, 1] == t)
    return np.ones_like(involves) if cfg.categories_with_target else ~involves


def category_masks(corr: np.ndarray, actions: Sequence[str], cfg: ExperimentConfig) -> np.ndarray:
    """``(T, A, K)`` bool: category k built at threshold T and usable by target t."""
    pairs = category_pairs(actions)
    above = np.stack([categories_above(corr, pairs, t) for t in cfg.thresholds])
    return above[:, None, :] & category_allowed(actions, cfg)[None]


def condition_plan(actions: Sequence[str], target: int, corr: np.ndarray, cfg: ExperimentConfig, space: str) -> list[tuple[int, tuple[int, ...]]]:
    """The conditions run for ``target``: ``[(condition index, bootstrap rows)]``.

    Bootstrap rows index the prep's outputs: rows 0..A-1 are the source predictors, A.. the
    categories. NB has no rows. CBn with no category left is NB's learner (same rows).
    """
    a = len(actions)
    lay = layout(a, len(cfg.thresholds))
    fams = cfg.conditions(space)
    plan: list[tuple[int, tuple[int, ...]]] = [(0, ())]
    others = tuple(s for s in range(a) if s != target)
    if "DB1" in fams:
        plan += [(int(lay["DB1"][s]), (s,)) for s in others]
    if "DBn" in fams:
        plan.append((int(lay["DBn"]), others))
    masks = category_masks(corr, actions, cfg)
    if "CB1" in fams:
        allowed = category_allowed(actions, cfg)[target]
        plan += [(int(lay["CB1"][k]), (a + k,)) for k in np.flatnonzero(allowed)]
    if "CBn" in fams:
        for ti in range(len(cfg.thresholds)):
            plan.append((int(lay["CBn"][ti]), tuple(int(a + k) for k in np.flatnonzero(masks[ti, target]))))
    return plan


def pool_sizes(n: int, cfg: ExperimentConfig) -> tuple[int, int, int]:
    """(source samples, correlation scenes, test scenes) of an action with ``n`` samples: the
    config's, or with ``shrink_to_data`` at most 40 %, 10 % and what the training sizes leave."""
    s, q, test = cfg.source_size, cfg.corr_scenes, cfg.test_size
    if cfg.shrink_to_data:
        s, q = min(s, int(0.4 * n)), min(q, int(0.1 * n))
        test = min(test, n - s - q - max(cfg.sizes))
    return int(s), int(q), int(test)


def split_pools(n: int, action_index: int, cfg: ExperimentConfig, seed: int) -> dict[str, np.ndarray]:
    """Disjoint index sets of one action's dataset: ``source`` (trains its source predictor
    and categories), ``corr`` (held-out scenes for the correlation heuristic), ``target``
    (train and test samples of its own affordance classifier), and the test size."""
    max_size = max(cfg.sizes)
    s, q, test = pool_sizes(n, cfg)
    need = s + q + max_size + test
    if n < need or min(s, q, test) < 1:
        raise UserError(
            f"{_action_names()[action_index]}: {n} samples, but the protocol needs {need} "
            f"(source {s} + correlation scenes {q} + training {max_size} + test {test}); "
            "use more data, smaller sizes (--set test_size=..., source_size=...), or the quick preset"
        )
    perm = np.random.default_rng(derive_seed(seed, streams.POOL_SPLIT, action_index)).permutation(n)
    return {"source": perm[:s], "corr": perm[s : s + q], "target": perm[s + q :], "test_size": np.asarray(test)}


def block_fits(plan: Sequence[tuple[int, tuple[int, ...]]], n_sizes: int, loo_size: int = 0,
               loo_conditions: Sequence[int] = (), repeats: int | dict[int, int] = 1) -> int:
    """Forests one block fits: one per distinct learner (bootstrap rows and their repeats,
    ``blocks.learner_key``) in ``plan`` and size (conditions with the same learner share it,
    ``blocks.block_outcomes``), plus, when the block holds the selection size, ``loo_size``
    leave-one-out forests per distinct learner among ``loo_conditions``."""
    # scikit-learn loads with the first fit: reproduce --status reads this module
    from relaff_jax.learn.blocks import learner_key

    key = lambda c, rows: learner_key(rows, repeats, c)  # noqa: E731
    loo = len({key(c, rows) for c, rows in plan if c in set(loo_conditions)}) * loo_size
    return len({key(c, rows) for c, rows in plan}) * n_sizes + loo


def condition_repeats(plan: Sequence[tuple[int, tuple[int, ...]]], cfg: ExperimentConfig, space: str,
                      n_actions: int) -> dict[int, int]:
    """``{condition: repeats}`` of a plan: every bootstrap input repeated ``cfg.repeats(space)``
    times, DBn's ``cfg.dbn_repeat(space)`` times (the paper leaves DBn's open: learning.md)."""
    dbn = int(layout(n_actions, len(cfg.thresholds))["DBn"])
    return {int(c): (cfg.dbn_repeat(space) if c == dbn else cfg.repeats(space)) for c, _ in plan}


def loo_conditions(n_actions: int, n_thresholds: int) -> tuple[int, ...]:
    """The candidates of the online "best after ten": every DB1 and CB1 condition."""
    lay = layout(n_actions, n_thresholds)
    return tuple(int(c) for c in np.concatenate([lay["DB1"], lay["CB1"]]))


def forests_per_space(cfg: ExperimentConfig, n_actions: int, space: str, corr: np.ndarray | None = None) -> int:
    """Forest fits of one space's whole run: the A source predictors, the A(A-1)/2 categories
    (when the space runs CB1 or CBn) and, per target, repetition and size, one forest per
    condition: NB, DB1 x (A-1), DBn, CB1 x (categories the target may use), CBn x thresholds.

    At ``select_size`` every DB1 and CB1 candidate also fits ``select_size`` leave-one-out
    forests per repetition (the online "best after ten"; not with ``online_select`` off).

    Without ``corr`` this is the count before the run (what a time estimate can know): every
    condition counted as its own forest. With the run's correlation matrix ``corr: (A, A)``
    it is the exact count the run makes: conditions of a target with the same bootstrap
    inputs share one forest (e.g. a CBn with no category kept is NB's learner; with two
    actions DBn is DB1), so it can be lower.
    """
    a = int(n_actions)
    k = a * (a - 1) // 2
    fams = cfg.conditions(space)
    prep = a + (k if {"CB1", "CBn"} & set(fams) else 0)
    if corr is None:
        usable = k if cfg.categories_with_target else (a - 1) * (a - 2) // 2
        per_target = (1 + ("DB1" in fams) * (a - 1) + ("DBn" in fams) + ("CB1" in fams) * usable
                      + ("CBn" in fams) * len(cfg.thresholds))
        loo = (("DB1" in fams) * (a - 1) + ("CB1" in fams) * usable) * cfg.select_size * (cfg.select_size in cfg.sizes) \
            * cfg.online_select
        sweep = a * (per_target * len(cfg.sizes) + loo)
    else:
        names = list(range(a))  # the plan depends on the number of actions only
        n_loo = cfg.select_size if cfg.select_size in cfg.sizes and cfg.online_select else 0
        cands = loo_conditions(a, len(cfg.thresholds))
        plans = [condition_plan(names, t, np.asarray(corr), cfg, space) for t in range(a)]
        sweep = sum(block_fits(p, len(cfg.sizes), n_loo, cands, condition_repeats(p, cfg, space, a)) for p in plans)
    return prep + sweep * cfg.reps(space)
