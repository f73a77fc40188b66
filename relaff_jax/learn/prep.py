"""Step 2 of the protocol, once per seed and space: source predictors, categories, correlation.

Takes ``{action: dataset}``, the space, the config and the seed; fits the A source predictors
(each on its action's source pool, in its own state order) and, when the space runs CB1 or
CBn, the A(A-1)/2 categories (each on the union of two source pools, canonical order), and
returns (``prepare``) their 0/1 outputs on every target pool and the correlation matrix of
the predictors on the held-out correlation scenes. Prep forests never see a target-pool scene.
Forests are fitted and evaluated by the forest engine (``engine.py``), another learner by
``learners.py`` (``ExperimentConfig.learner``).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from relaff_jax.constants import ACTIONS
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.sim.actions.registry import action_id, names  # the run's actions: the nine, then a user's; no JAX
from relaff_jax.learn.correlation import category_pairs, correlation_matrix, correlation_with
from relaff_jax.learn.datasets import check_datasets
from relaff_jax.config.experiment import ForestConfig
from relaff_jax.learn.learners import SklearnLearner, fit, learner_of, predict
from relaff_jax.learn.parallel import run_parallel
from relaff_jax.learn.protocol import split_pools
from relaff_jax.config.experiment import StateConfig
from relaff_jax.learn.states import state_features
from relaff_jax.provenance import derive_seed
from relaff_jax.config import streams


def _source_job(feats: dict, action: str, labels: np.ndarray, src: np.ndarray, actions: list[str],
                targets: dict, corr_idx: dict, space: str, seed: int, fcfg: ForestConfig | SklearnLearner,
                scfg: StateConfig = StateConfig()):
    """Fit one action's source predictor; predict every target pool and the corr scenes."""
    def states(b: str, idx: np.ndarray) -> np.ndarray:  # scenes of action b in this source's order
        return state_features(feats[b]["pca"][idx], feats[b]["rhf"][idx] if space == "rhf" else None, action, space, scfg)

    forest = fit(states(action, src), labels[src], derive_seed(seed, streams.SOURCE_FOREST, streams.SPACE_CODE[space], action_id(action)), fcfg)

    def on(b: str, idx: np.ndarray) -> np.ndarray:
        return predict(forest, states(b, idx))

    return [on(t, targets[t]) for t in actions], np.concatenate([on(b, corr_idx[b]) for b in actions])


def _source_on_sources(feats: dict, action: str, labels: np.ndarray, src: dict, space: str, seed: int,
                       fcfg: ForestConfig | SklearnLearner, scfg: StateConfig = StateConfig()) -> dict:
    """``{b: (len(src[b]),)}`` the action's source predictor (the same forest as ``_source_job``'s:
    same data and seed) on every other action's source scenes: the other affordance's label
    where the dataset has none (``category_labels`` both / either)."""
    def states(b: str, idx: np.ndarray) -> np.ndarray:
        return state_features(feats[b]["pca"][idx], feats[b]["rhf"][idx] if space == "rhf" else None, action, space, scfg)

    forest = fit(states(action, src[action]), labels[src[action]],
                 derive_seed(seed, streams.SOURCE_FOREST, streams.SPACE_CODE[space], action_id(action)), fcfg)
    return {b: predict(forest, states(b, src[b])) for b in src if b != action}


def category_labels(pair: tuple[str, str], labels: dict, src: dict, other: dict | None, reading: str) -> np.ndarray:
    """The labels a category of ``pair`` trains on, over the union of the two source sets (a's
    scenes, then b's): ``union`` each scene with its own action's label (the default); ``both`` /
    ``either``: its own label and / or the other action's, which its dataset lacks, predicted by
    that action's source predictor (``other[x][y]``: x's predictor on y's source scenes)."""
    a, b = pair
    own_a, own_b = labels[a][src[a]], labels[b][src[b]]
    if reading == "union":
        return np.concatenate([own_a, own_b])
    op = np.logical_and if reading == "both" else np.logical_or
    return np.concatenate([op(own_a, np.asarray(other[b][a]) > 0.5), op(own_b, np.asarray(other[a][b]) > 0.5)])


def _category_index(a: str, b: str) -> int:
    """The seed index of category (a, b): its place among the nine's 36 (as before actions were
    specs), or, with a user action, 36 + its place among the run's other pairs."""
    if a in ACTIONS and b in ACTIONS:
        return category_pairs(ACTIONS).index((ACTIONS.index(a), ACTIONS.index(b)))
    ids = names()
    extra = [p for p in category_pairs(ids) if max(p) >= len(ACTIONS)]
    return len(category_pairs(ACTIONS)) + extra.index((ids.index(a), ids.index(b)))


def _category_job(feats: dict, pair: tuple[str, str], labels: dict, src: dict, actions: list[str],
                  targets: dict, space: str, seed: int, fcfg: ForestConfig | SklearnLearner, scfg: StateConfig = StateConfig(),
                  y: np.ndarray | None = None):
    """Fit one category on the union of two source sets (canonical order: toy first), labelled
    ``y`` (default: each scene its own action's label, ``category_labels`` "union")."""
    def canon(b: str, idx: np.ndarray) -> np.ndarray:
        return state_features(feats[b]["pca"][idx], feats[b]["rhf"][idx] if space == "rhf" else None, None, space, scfg)

    a, b = pair
    x = np.concatenate([canon(a, src[a]), canon(b, src[b])])
    y = np.concatenate([labels[a][src[a]], labels[b][src[b]]]) if y is None else np.asarray(y, bool)
    k = _category_index(a, b)
    forest = fit(x, y, derive_seed(seed, streams.CATEGORY_FOREST, streams.SPACE_CODE[space], k), fcfg)
    return [predict(forest, canon(t, targets[t])) for t in actions]


def prepare(datasets: Mapping[str, Mapping[str, Any]], space: str, cfg: ExperimentConfig, seed: int,
            jobs: int = 1, progress: bool = False, client: Any = None) -> dict[str, np.ndarray]:
    """Source predictors, categories and the correlation heuristic for one space (its forests
    as tasks on ``client``'s cluster when given).

    Returns a flat dict of arrays: ``boot:<t>`` (A + K, M_t) 0/1 outputs on target t's pool
    (rows: the A source predictors, then the K categories; NaN rows for categories a space
    does not use, so a misuse cannot pass silently), ``target:<t>`` (M_t,) pool
    indices, ``test_size:<t>``, ``corr`` (A, A), ``corr_n`` (scenes used).
    """
    from joblib import delayed

    actions = check_datasets(datasets, [space])
    pools = {a: split_pools(len(datasets[a]["label"]), action_id(a), cfg, seed) for a in actions}
    feats = {a: {k: np.asarray(datasets[a][k], dtype=np.float32) for k in (("pca", "rhf") if space == "rhf" else ("pca",))} for a in actions}
    labels = {a: np.asarray(datasets[a]["label"]).astype(bool) for a in actions}
    targets = {a: pools[a]["target"] for a in actions}
    src = {a: pools[a]["source"] for a in actions}
    corr_idx = {a: pools[a]["corr"] for a in actions}
    pairs = [(actions[i], actions[j]) for i, j in category_pairs(actions)]
    # categories are only trained when this space uses them (the paper's RHF runs NB and DB1)
    with_cats = bool({"CB1", "CBn"} & set(cfg.conditions(space)))
    learner = learner_of(cfg)  # the paper's forest (ForestConfig) or a scikit-learn classifier
    calls = [delayed(_source_job)(feats, a, labels[a], src[a], actions, targets, corr_idx, space, seed, learner,
                                  cfg.state) for a in actions]
    ys = {p: None for p in pairs}
    if with_cats and cfg.category_labels != "union":  # the other affordance's labels: the source predictors'
        other_calls = [delayed(_source_on_sources)(feats, a, labels[a], src, space, seed, learner, cfg.state)
                       for a in actions]
        other = dict(zip(actions, run_parallel(other_calls, jobs, progress, total=len(actions),
                                               desc=f"{space} source predictors on the source scenes", unit="forest",
                                               client=client)))
        ys = {p: category_labels(p, labels, src, other, cfg.category_labels) for p in pairs}
    calls += [delayed(_category_job)(feats, p, labels, src, actions, targets, space, seed, learner, cfg.state, ys[p])
              for p in pairs] if with_cats else []
    desc = f"{space} source predictors" + (" + categories" if with_cats else "")
    results = run_parallel(calls, jobs, progress, total=len(calls), desc=desc, unit="forest", client=client)
    sources = results[: len(actions)]
    cats = results[len(actions) :] if with_cats else [[np.full(len(targets[t]), np.nan, np.float32) for t in actions]] * len(pairs)
    out: dict[str, np.ndarray] = {}
    for ti, t in enumerate(actions):
        rows = [sources[s][0][ti] for s in range(len(actions))] + [c[ti] for c in cats]
        out[f"boot:{t}"] = np.stack(rows).astype(np.float32)
        out[f"target:{t}"] = targets[t]
        out[f"test_size:{t}"] = pools[t]["test_size"]
    corr_out = np.stack([s[1] for s in sources])
    out["corr"] = correlation_matrix(corr_out)
    out["corr_outputs_mean"] = corr_out.mean(axis=1)
    out["corr_n"] = np.asarray(corr_out.shape[1])
    # what each predictor has learned: its outputs on the same scenes against reach and relation
    feasible = np.concatenate([_feasible(datasets[b], corr_idx[b]) for b in actions])
    stacked = np.concatenate([_stacked(datasets[b], corr_idx[b]) for b in actions])
    out["corr_feasible"] = correlation_with(corr_out, feasible)
    out["corr_stacked"] = correlation_with(corr_out, stacked)
    return out


def _stacked(ds: Mapping[str, Any], idx: np.ndarray) -> np.ndarray:
    """(len(idx),) float: 1 where the toy is on top of or inside the other object; NaN without relations."""
    if "relation" not in ds:
        return np.full(len(idx), np.nan)
    return (np.asarray(ds["relation"]).astype(str)[idx] != "beside").astype(float)


def _feasible(ds: Mapping[str, Any], idx: np.ndarray) -> np.ndarray:
    """(len(idx),) float: 1 where the motor program was executable; NaN without the field."""
    if "feasible" not in ds:
        return np.full(len(idx), np.nan)
    return np.asarray(ds["feasible"]).astype(float)[idx]
