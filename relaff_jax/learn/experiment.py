"""The evaluation protocol of paper section V: sweeps, bootstrap factors and Table II.

Takes the nine featured datasets (``{action: load_dataset(DIR)}``, or ``synthetic_datasets``)
and returns, per state space, accuracies ``acc: (target, condition, size, rep)`` on disk
(``RESULTS/<space>/results.npz``), from which bootstrap factors, the average bootstrap factor
over n = 4..25 and Table II follow as array operations.

Protocol (docs/learning.md has the full story):

1. Pools, once per seed and action: each action's dataset is shuffled and split into a
   *source pool* (``source_size`` samples that train that action's source predictor, plus
   ``corr_scenes`` held-out scenes for the correlation heuristic) and a disjoint *target
   pool* (everything else). Source predictors and categories never see a target-pool scene
   during training, so they are disjoint from every target training and test sample.
2. Prep, once per seed and space: nine source predictors (each on its action's
   ``source_size`` samples, 2000 in the paper preset, as the heuristic's predictors in
   paper V-F) and the 36 categories (each on the union of two source sets); their 0/1
   predictions on every target pool; the 9 x 9 correlation matrix of the predictors on the
   union of the held-out correlation scenes.
3. Sweep, one block per (target, repetition, chunk of sizes): the target pool is permuted
   (same permutation for PCA and RHF); the first ``test_size`` samples are the test set,
   the next ``max(sizes)`` are the training order, and size n trains on its first n
   (nested training sets, shared by every condition: paired comparisons). For every
   condition (NB, DB1 x 8, DBn, CB1 x 28, CBn x 3 thresholds) and size one forest is fitted
   and its accuracy on the test set recorded. Blocks are written atomically, so a killed
   sweep resumes with the finished blocks.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import time
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.config import from_dict, override, to_dict
from relaff_jax.constants import FAMILIES
from relaff_jax.learn.forests import (
    ACTIONS,
    SPACES,
    ForestConfig,
    augment,
    check_forest_config,
    categories_above,
    category_pairs,
    correlation_matrix,
    fit_forest,
    predict_class,
    state_features,
    synthetic_datasets,
)

SPACE_CODE = {"pca": 0, "rhf": 1}
FORMAT_VERSION = 1

# Paper Table II (PCA, average bootstrap factor over n = 4..25): avg, min, max over the
# nine affordances.
TABLE2_ROWS = (
    "NB", "DB1 average", "DB1 best", "DB1 best after ten", "DBn",
    "CB1 average", "CB1 best", "CB1 best after ten", "CBn",
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


@dataclasses.dataclass(frozen=True)
class ExperimentConfig:
    """Protocol settings; defaults are the paper's (section V, REFERENCE section 6)."""

    sizes: tuple[int, ...] = tuple(range(2, 101))  # training sizes n
    reps_pca: int = 50
    reps_rhf: int = 25
    test_size: int = 4000
    source_size: int = 2000  # samples per source predictor (and per half of a category)
    corr_scenes: int = 500  # held-out scenes per action shown to all nine predictors
    shrink_to_data: bool = False  # quick preset: shrink source/corr/test sizes to small datasets
    repeats_pca: int = 6  # bootstrap input repetitions (24-dim PCA state with one input)
    repeats_rhf: int = 30  # (348-dim RHF state with one input)
    thresholds: tuple[float, ...] = (0.0, 0.125, 0.5)  # correlation heuristic, paper V-F
    cbn_threshold: float = 0.5  # categories used by CBn in Table II (paper V-G)
    categories_with_target: bool = False  # may a category built from the target itself be used?
    conditions_pca: tuple[str, ...] = FAMILIES
    conditions_rhf: tuple[str, ...] = ("NB", "DB1")  # the paper shows only NB and DB1 in RHF
    bf_sizes: tuple[int, int] = (4, 25)  # average bootstrap factor interval (paper V-C)
    best_sizes: tuple[int, int] = (2, 100)  # "best" = highest mean accuracy over these n
    select_size: int = 10  # "best after ten"
    chance: float = 0.5
    sizes_per_block: int = 25
    forest: ForestConfig = ForestConfig()

    def reps(self, space: str) -> int:
        return self.reps_pca if space == "pca" else self.reps_rhf

    def repeats(self, space: str) -> int:
        return self.repeats_pca if space == "pca" else self.repeats_rhf

    def conditions(self, space: str) -> tuple[str, ...]:
        return self.conditions_pca if space == "pca" else self.conditions_rhf


def preset(name: str) -> ExperimentConfig:
    """``paper``: the full protocol. ``quick``: every condition at 5 sizes, 2 repetitions,
    2000 test samples, shrunk to small datasets; ~4.5k forests, minutes on 2 cores."""
    if name == "paper":
        return ExperimentConfig()
    if name == "quick":
        return ExperimentConfig(
            sizes=(2, 4, 10, 25, 50), reps_pca=2, reps_rhf=2, test_size=2000, shrink_to_data=True,
        )
    raise ValueError(f"unknown preset {name!r}; expected 'quick' or 'paper'")


def check_config(cfg: ExperimentConfig) -> None:
    sizes = np.asarray(cfg.sizes)
    if sizes.ndim != 1 or len(sizes) == 0 or np.any(sizes < 2) or np.any(np.diff(sizes) <= 0):
        raise ValueError(f"sizes must be strictly increasing integers >= 2, got {cfg.sizes}")
    if cfg.select_size not in cfg.sizes:
        raise ValueError(f"select_size {cfg.select_size} ('best after ten') must be one of sizes {cfg.sizes}")
    if not any(cfg.bf_sizes[0] <= s <= cfg.bf_sizes[1] for s in cfg.sizes):
        raise ValueError(f"no training size inside bf_sizes {cfg.bf_sizes}")
    if cfg.cbn_threshold not in cfg.thresholds:
        raise ValueError(f"cbn_threshold {cfg.cbn_threshold} must be one of thresholds {cfg.thresholds}")
    for space in SPACES:
        bad = set(cfg.conditions(space)) - set(FAMILIES)
        if bad or "NB" not in cfg.conditions(space):
            raise ValueError(f"conditions_{space} must include NB and be among {FAMILIES}, got {cfg.conditions(space)}")
    check_forest_config(cfg.forest)
    if min(cfg.reps_pca, cfg.reps_rhf, cfg.test_size, cfg.source_size, cfg.corr_scenes, cfg.sizes_per_block) < 1:
        raise ValueError("reps, test_size, source_size, corr_scenes and sizes_per_block must be >= 1")


def _seed(*keys: int) -> int:
    """A 32-bit seed from integer keys (independent streams for every random quantity)."""
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0])


# ------------------------------------------------------------------------- conditions


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


# -------------------------------------------------------------------------------- data


def check_datasets(datasets: Mapping[str, Mapping[str, Any]], spaces: Sequence[str]) -> list[str]:
    """Validate ``{action: dataset}``; return the present actions in canonical order."""
    if len(datasets) < 2:
        raise ValueError(f"bootstrapping needs datasets of at least two actions, got {sorted(datasets)}")
    for action, d in datasets.items():
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r}; expected one of {ACTIONS}")
        if "action" in d and str(d["action"]) != action:
            raise ValueError(f"dataset given for {action!r} says its action is {d['action']!r}")
        for key in ("label", "pca") + (("rhf",) if "rhf" in spaces else ()):
            if key not in d:
                raise ValueError(f"{action} dataset has no {key!r} array (needed for spaces {list(spaces)})")
        n = len(d["label"])
        if np.shape(d["pca"]) != (n, 18):
            raise ValueError(f"{action}: pca must be (N, 18) with N = {n} labels, got {np.shape(d['pca'])}")
        if "rhf" in spaces and np.shape(d["rhf"]) != (n, 300):
            raise ValueError(f"{action}: rhf must be (N, 300) with N = {n} labels, got {np.shape(d['rhf'])}")
        for key in ("pca",) + (("rhf",) if "rhf" in spaces else ()):
            if not np.all(np.isfinite(d[key])):
                raise ValueError(f"{action}: {key} features contain NaN or inf")
    return [a for a in ACTIONS if a in datasets]


def fingerprint(datasets: Mapping[str, Mapping[str, Any]], spaces: Sequence[str]) -> dict[str, dict[str, str]]:
    """``{space: {action: sha256}}`` of the labels and the space's features: a resumed sweep
    must see the same data."""
    out: dict[str, dict[str, str]] = {}
    for space in spaces:
        out[space] = {}
        for action in sorted(datasets):
            h = hashlib.sha256()
            for key in ("label", "pca") + (("rhf",) if space == "rhf" else ()):
                h.update(np.ascontiguousarray(np.asarray(datasets[action][key], dtype=np.float32)).tobytes())
            out[space][action] = h.hexdigest()
    return out


def load_datasets(dirs: Sequence[str | os.PathLike]) -> dict[str, dict]:
    """``{action: load_dataset(DIR)}`` for the given dataset directories."""
    try:
        from relaff_jax.data.dataset import load_dataset
    except ImportError as e:  # the dataset stage is another module
        raise ValueError(f"cannot read datasets: relaff_jax.dataset.load_dataset is unavailable ({e})") from e
    out: dict[str, dict] = {}
    for d in dirs:
        data = load_dataset(d)
        action = str(data["action"])
        if action in out:
            raise ValueError(f"two datasets for action {action!r} (second: {d})")
        out[action] = data
    return out


def split_pools(n: int, action_index: int, cfg: ExperimentConfig, seed: int) -> dict[str, np.ndarray]:
    """Disjoint index sets of one action's dataset: ``source`` (trains its source predictor
    and categories), ``corr`` (held-out scenes for the correlation heuristic), ``target``
    (train and test samples of its own affordance classifier), and the test size."""
    max_size = max(cfg.sizes)
    s, q, test = cfg.source_size, cfg.corr_scenes, cfg.test_size
    if cfg.shrink_to_data:
        s, q = min(s, int(0.4 * n)), min(q, int(0.1 * n))
        test = min(test, n - s - q - max_size)
    need = s + q + max_size + test
    if n < need or min(s, q, test) < 1:
        raise ValueError(
            f"{ACTIONS[action_index]}: {n} samples, but the protocol needs {need} "
            f"(source {s} + correlation scenes {q} + training {max_size} + test {test}); "
            "use more data, smaller sizes (--set test_size=..., source_size=...), or the quick preset"
        )
    perm = np.random.default_rng(_seed(seed, 1, action_index)).permutation(n)
    return {"source": perm[:s], "corr": perm[s : s + q], "target": perm[s + q :], "test_size": np.asarray(test)}


def draw_rep(m: int, test_size: int, max_size: int, seed: int, target_index: int, rep: int) -> tuple[np.ndarray, np.ndarray]:
    """Test indices ``(test_size,)`` and training order ``(max_size,)`` into a target pool of
    size m for one repetition; the same in both spaces."""
    perm = np.random.default_rng(_seed(seed, 4, target_index, rep)).permutation(m)
    return perm[:test_size], perm[test_size : test_size + max_size]


# ------------------------------------------------------------------------------- prep


def _source_job(feats: dict, action: str, labels: np.ndarray, src: np.ndarray, actions: list[str],
                targets: dict, corr_idx: dict, space: str, seed: int, fcfg: ForestConfig):
    """Fit one action's source predictor; predict every target pool and the corr scenes."""
    def states(b: str, idx: np.ndarray) -> np.ndarray:  # scenes of action b in this source's order
        return state_features(feats[b]["pca"][idx], feats[b]["rhf"][idx] if space == "rhf" else None, action, space)

    forest = fit_forest(states(action, src), labels[src], _seed(seed, 2, SPACE_CODE[space], ACTIONS.index(action)), fcfg)

    def on(b: str, idx: np.ndarray) -> np.ndarray:
        return predict_class(forest, states(b, idx))

    return [on(t, targets[t]) for t in actions], np.concatenate([on(b, corr_idx[b]) for b in actions])


def _category_job(feats: dict, pair: tuple[str, str], labels: dict, src: dict, actions: list[str],
                  targets: dict, space: str, seed: int, fcfg: ForestConfig):
    """Fit one category on the union of two source sets (canonical order: toy first)."""
    def canon(b: str, idx: np.ndarray) -> np.ndarray:
        return state_features(feats[b]["pca"][idx], feats[b]["rhf"][idx] if space == "rhf" else None, None, space)

    a, b = pair
    x = np.concatenate([canon(a, src[a]), canon(b, src[b])])
    y = np.concatenate([labels[a][src[a]], labels[b][src[b]]])
    k = category_pairs(ACTIONS).index((ACTIONS.index(a), ACTIONS.index(b)))
    forest = fit_forest(x, y, _seed(seed, 3, SPACE_CODE[space], k), fcfg)
    return [predict_class(forest, canon(t, targets[t])) for t in actions]


def prepare(datasets: Mapping[str, Mapping[str, Any]], space: str, cfg: ExperimentConfig, seed: int,
            jobs: int = 1, progress: bool = False) -> dict[str, np.ndarray]:
    """Source predictors, categories and the correlation heuristic for one space.

    Returns a flat dict of arrays: ``boot:<t>`` (A + K, M_t) 0/1 outputs on target t's pool
    (rows: the A source predictors, then the K categories; NaN rows for categories a space
    does not use, so a misuse cannot pass silently), ``target:<t>`` (M_t,) pool
    indices, ``test_size:<t>``, ``corr`` (A, A), ``corr_n`` (scenes used).
    """
    from joblib import delayed

    actions = check_datasets(datasets, [space])
    pools = {a: split_pools(len(datasets[a]["label"]), ACTIONS.index(a), cfg, seed) for a in actions}
    feats = {a: {k: np.asarray(datasets[a][k], dtype=np.float32) for k in (("pca", "rhf") if space == "rhf" else ("pca",))} for a in actions}
    labels = {a: np.asarray(datasets[a]["label"]).astype(bool) for a in actions}
    targets = {a: pools[a]["target"] for a in actions}
    src = {a: pools[a]["source"] for a in actions}
    corr_idx = {a: pools[a]["corr"] for a in actions}
    pairs = [(actions[i], actions[j]) for i, j in category_pairs(actions)]
    # categories are only trained when this space uses them (the paper's RHF runs NB and DB1)
    with_cats = bool({"CB1", "CBn"} & set(cfg.conditions(space)))
    calls = [delayed(_source_job)(feats, a, labels[a], src[a], actions, targets, corr_idx, space, seed, cfg.forest) for a in actions]
    calls += [delayed(_category_job)(feats, p, labels, src, actions, targets, space, seed, cfg.forest) for p in pairs] if with_cats else []
    desc = f"{space} source predictors" + (" + categories" if with_cats else "")
    results = _run_parallel(calls, jobs, progress, total=len(calls), desc=desc, unit="forest")
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
    return out


def _run_parallel(calls: list, jobs: int, progress: bool, total: int, desc: str, unit: str, weights=None, initial: int = 0) -> list:
    """Run joblib ``calls`` over ``jobs`` processes, in order, with a progress bar."""
    from joblib import Parallel
    from tqdm import tqdm

    weights = [1] * len(calls) if weights is None else weights
    bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, disable=not progress, smoothing=0, dynamic_ncols=True)
    results: list = [None] * len(calls)
    try:
        if jobs == 1:
            for i, c in enumerate(calls):
                fn, args, kwargs = c
                results[i] = fn(*args, **kwargs)
                bar.update(weights[i])
        else:
            indexed = [(_indexed, (i, c), {}) for i, c in enumerate(calls)]
            for i, r in Parallel(n_jobs=jobs, return_as="generator_unordered")(indexed):
                results[i] = r
                bar.update(weights[i])
    finally:
        bar.close()
    return results


def _indexed(i: int, call):
    fn, args, kwargs = call
    return i, fn(*args, **kwargs)


# ------------------------------------------------------------------------------ blocks


def run_block(X: np.ndarray, y: np.ndarray, boot: np.ndarray, plan: Sequence[tuple[int, tuple[int, ...]]],
              train_order: np.ndarray, test_idx: np.ndarray, sizes: Sequence[int], repeats: int,
              n_conditions: int, forest: ForestConfig, seed_keys: Sequence[int]) -> np.ndarray:
    """Accuracies ``(C, len(sizes))`` of one (target, repetition) over a chunk of sizes.

    X: (M, D) target-pool states in the target's order; y: (M,) labels; boot: (R, M) 0/1
    bootstrap inputs on the same scenes; plan: ``[(condition, rows of boot)]``; train_order:
    (>= max(sizes),) training sample order (size n uses its first n); test_idx: (T,).
    Conditions not in the plan stay NaN. Conditions with the same rows share one learner.
    Forest seeds come from ``seed_keys`` + (n, first condition with these rows).
    """
    acc = np.full((n_conditions, len(sizes)), np.nan)
    first: dict[tuple[int, ...], int] = {}
    y = np.asarray(y).astype(bool)
    for cond, rows in plan:
        if rows in first:
            acc[cond] = acc[first[rows]]
            continue
        first[rows] = cond
        inputs = boot[list(rows)]
        if not np.all(np.isfinite(inputs)):
            raise ValueError(f"condition {cond}: bootstrap inputs {rows} were not computed for this space")
        xc = augment(X, inputs, repeats)
        x_test, y_test = xc[test_idx], y[test_idx]
        for si, n in enumerate(sizes):
            tr = train_order[:n]
            f = fit_forest(xc[tr], y[tr], _seed(*seed_keys, n, cond), forest)
            acc[cond, si] = np.mean(predict_class(f, x_test).astype(bool) == y_test)
    return acc


def _block_job(path: str, X, y, boot, plan, train_order, test_idx, sizes, repeats, n_conditions, forest, seed_keys):
    acc = run_block(X, y, boot, plan, train_order, test_idx, sizes, repeats, n_conditions, forest, seed_keys)
    rio.atomic_save_npz(path, acc=acc, sizes=np.asarray(sizes))
    return acc


def _read_block(path: Path, n_conditions: int, sizes: Sequence[int]) -> np.ndarray | None:
    """A finished block, or None if missing or unreadable (then it is recomputed)."""
    if not path.exists():
        return None
    try:
        with np.load(path) as z:
            acc, s = z["acc"], z["sizes"]
    except Exception:  # a corrupt file cannot be a finished block (writes are atomic)
        return None
    if acc.shape != (n_conditions, len(sizes)) or list(s) != list(sizes):
        return None
    return acc


def block_fits(plan, n_sizes: int) -> int:
    return len({rows for _, rows in plan}) * n_sizes


# ------------------------------------------------------------------------------- sweep


def run_experiment(datasets: Mapping[str, Mapping[str, Any]], out: str | os.PathLike, cfg: ExperimentConfig,
                   spaces: Sequence[str] = SPACES, seed: int = 0, jobs: int = 1, progress: bool = True,
                   data_desc: Sequence[str] = ()) -> dict[str, Path]:
    """Run (or resume) the protocol; write ``out/<space>/results.npz``; return their paths.

    ``out/experiment.json`` records config, seed, actions and a data fingerprint; resuming
    with different ones is an error (start a new ``out`` instead).
    """
    check_config(cfg)
    spaces = list(dict.fromkeys(spaces))
    for s in spaces:
        if s not in SPACES:
            raise ValueError(f"unknown space {s!r}; expected one of {SPACES}")
    actions = check_datasets(datasets, spaces)
    out = Path(out)
    meta = {
        "format": FORMAT_VERSION,
        "config": to_dict(cfg),
        "seed": int(seed),
        "actions": actions,
        "spaces": spaces,
        "fingerprint": fingerprint(datasets, spaces),
    }
    meta_path = out / "experiment.json"
    if meta_path.exists():
        # same protocol, seed, actions and data; a space may be added to a finished one
        old = rio.read_json(meta_path)
        now = json.loads(json.dumps(meta, default=rio._json_default))
        diff = [k for k in ("format", "config", "seed", "actions") if old.get(k) != now[k]]
        diff += [f"{s} data" for s in spaces if s in old.get("fingerprint", {}) and old["fingerprint"][s] != now["fingerprint"][s]]
        if diff:
            raise ValueError(f"{out} holds an experiment with different {diff}; use a new --out to start another")
        if set(spaces) - set(old["spaces"]):
            old["spaces"] = [s for s in SPACES if s in set(old["spaces"]) | set(spaces)]
            old["fingerprint"] = dict(old["fingerprint"], **now["fingerprint"])
            rio.atomic_write_json(meta_path, old)
    else:
        rio.atomic_write_json(meta_path, dict(meta, data=list(map(str, data_desc)), started=time.strftime("%Y-%m-%d %H:%M:%S")))
    paths = {}
    for space in spaces:
        paths[space] = _run_space(datasets, out / space, cfg, space, actions, seed, jobs, progress)
    return paths


def _run_space(datasets, sdir: Path, cfg: ExperimentConfig, space: str, actions: list[str], seed: int,
               jobs: int, progress: bool) -> Path:
    t0 = time.perf_counter()
    prep_path = sdir / "prep.npz"
    if prep_path.exists():
        with np.load(prep_path) as z:
            prep = {k: z[k] for k in z.files}
    else:
        prep = prepare(datasets, space, cfg, seed, jobs, progress)
        rio.atomic_save_npz(prep_path, **prep)
    t_prep = time.perf_counter() - t0
    a, sizes, reps = len(actions), list(cfg.sizes), cfg.reps(space)
    n_cond = layout(a, len(cfg.thresholds))["n"]
    chunks = [sizes[i : i + cfg.sizes_per_block] for i in range(0, len(sizes), cfg.sizes_per_block)]
    corr = prep["corr"]
    plans = [condition_plan(actions, ti, corr, cfg, space) for ti in range(a)]
    acc = np.full((a, n_cond, len(sizes), reps), np.nan)
    calls, weights, done_fits, total_fits = [], [], 0, 0
    keys = []
    target_data: dict[str, tuple] = {}  # (X, y, boot) per target, built once, shared by all its blocks
    for r in range(reps):  # repetitions outermost: early blocks are representative for the ETA
        for ti, t in enumerate(actions):
            pool = prep[f"target:{t}"]
            draws = None
            for ci, chunk in enumerate(chunks):
                path = sdir / "blocks" / f"{t}_r{r:03d}_c{ci:02d}.npz"
                fits = block_fits(plans[ti], len(chunk))
                total_fits += fits
                s0 = sizes.index(chunk[0])
                got = _read_block(path, n_cond, chunk)
                if got is not None:
                    acc[ti, :, s0 : s0 + len(chunk), r] = got
                    done_fits += fits
                    continue
                if t not in target_data:
                    ds = datasets[t]
                    target_data[t] = (
                        state_features(np.asarray(ds["pca"])[pool], np.asarray(ds["rhf"])[pool] if space == "rhf" else None, t, space),
                        np.asarray(ds["label"]).astype(bool)[pool],
                        prep[f"boot:{t}"],
                    )
                if draws is None:
                    draws = draw_rep(len(pool), int(prep[f"test_size:{t}"]), max(sizes), seed, ACTIONS.index(t), r)
                X, y, boot = target_data[t]
                test_idx, train_order = draws
                seed_keys = (seed, 5, SPACE_CODE[space], ACTIONS.index(t), r)
                calls.append((_block_job, (str(path), X, y, boot, plans[ti], train_order, test_idx, chunk,
                                           cfg.repeats(space), n_cond, cfg.forest, seed_keys), {}))
                weights.append(fits)
                keys.append((ti, s0, len(chunk), r))
    results = _run_parallel(calls, jobs, progress, total=total_fits, desc=f"{space} sweep", unit="fit",
                            weights=weights, initial=done_fits)
    for (ti, s0, n, r), got in zip(keys, results):
        acc[ti, :, s0 : s0 + n, r] = got
    masks = category_masks(corr, actions, cfg)
    res_path = sdir / "results.npz"
    rio.atomic_save_npz(
        res_path,
        acc=acc,
        sizes=np.asarray(sizes),
        actions=np.asarray(actions),
        conditions=np.asarray(condition_names(actions, cfg.thresholds)),
        thresholds=np.asarray(cfg.thresholds, dtype=float),
        corr=corr,
        category_masks=masks,
        test_size=np.asarray([int(prep[f"test_size:{t}"]) for t in actions]),
        seconds=np.asarray(time.perf_counter() - t0),
        seconds_prep=np.asarray(t_prep),
        new_fits=np.asarray(sum(weights)),
    )
    return res_path


def is_complete(out: str | os.PathLike, spaces: Sequence[str] = SPACES) -> bool:
    """Whether ``out`` holds finished results for every one of ``spaces``."""
    out = Path(out)
    if not (out / "experiment.json").exists():
        return False
    try:
        done = rio.read_json(out / "experiment.json")["spaces"]
    except (ValueError, KeyError):
        return False
    return all(s in done and (out / s / "results.npz").exists() for s in spaces)


# ------------------------------------------------------------------------------ analysis


def load_results(results_dir: str | os.PathLike) -> dict[str, Any]:
    """``{"meta": experiment.json, "config": ExperimentConfig, <space>: {arrays}}``."""
    root = Path(results_dir)
    meta_path = root / "experiment.json"
    if not meta_path.exists():
        raise FileNotFoundError(f"{root} is not an experiment folder (no experiment.json)")
    meta = rio.read_json(meta_path)
    out: dict[str, Any] = {"meta": meta, "config": from_dict(ExperimentConfig, meta["config"])}
    for space in meta["spaces"]:
        p = root / space / "results.npz"
        if not p.exists():
            raise FileNotFoundError(f"{p} missing: the {space} sweep has not finished (rerun `relaff experiment`)")
        with np.load(p) as z:
            out[space] = {k: z[k] for k in z.files}
    return out


def curves(acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over repetitions: ``acc (..., S, R) -> (..., S), (..., S)``."""
    with np.errstate(invalid="ignore"), _quiet():
        mean = np.nanmean(acc, axis=-1)
        n = np.sum(np.isfinite(acc), axis=-1)
        sem = np.nanstd(acc, axis=-1, ddof=1) / np.sqrt(n) if acc.shape[-1] > 1 else np.zeros_like(mean)
    return mean, sem


def bootstrap_factor(p_bl: np.ndarray, p_sl: np.ndarray, chance: float = 0.5) -> np.ndarray:
    """bf = (P_bl - P_c) / (P_sl - P_c) (paper III-D), broadcast; NaN where P_sl <= P_c
    (the standard learner is at or below chance and the ratio has no meaning)."""
    p_bl, p_sl = np.asarray(p_bl, dtype=float), np.asarray(p_sl, dtype=float)
    den = p_sl - chance
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, (p_bl - chance) / np.where(den > 0, den, 1.0), np.nan)


def size_mask(sizes: Sequence[int], lo: int, hi: int) -> np.ndarray:
    s = np.asarray(sizes)
    return (s >= lo) & (s <= hi)


def average_bf(bf: np.ndarray, sizes: Sequence[int], lo: int = 4, hi: int = 25) -> np.ndarray:
    """Average bootstrap factor: mean of ``bf (..., S)`` over sizes lo <= n <= hi (paper V-C)."""
    with _quiet():
        return np.nanmean(np.asarray(bf)[..., size_mask(sizes, lo, hi)], axis=-1)


def select_best(p: np.ndarray, sizes: Sequence[int], lo: int = 2, hi: int = 100) -> np.ndarray:
    """Index of the candidate with the highest mean accuracy over sizes lo..hi:
    ``p (..., K, S) -> (...,)``; NaN candidates (not run / not allowed) never win."""
    mask = size_mask(sizes, lo, hi)
    mask = mask if mask.any() else np.ones_like(mask)
    with _quiet():
        return _nanargmax(np.nanmean(np.asarray(p)[..., mask], axis=-1))


def select_at(p: np.ndarray, sizes: Sequence[int], n: int = 10) -> np.ndarray:
    """Index of the candidate with the highest mean accuracy at training size n ("best after ten")."""
    return _nanargmax(np.asarray(p)[..., list(sizes).index(n)])


def _nanargmax(score: np.ndarray) -> np.ndarray:
    s = np.where(np.isfinite(score), score, -np.inf)
    return np.argmax(s, axis=-1)


class _quiet:
    """Silence numpy's 'mean of empty slice' warnings for all-NaN slices (they give NaN)."""

    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


def analyse(res: Mapping[str, np.ndarray], cfg: ExperimentConfig) -> dict[str, Any]:
    """Everything section V reports for one space, as arrays over (target, condition, size).

    Returns mean/sem curves ``(A, C, S)``, bf curves ``(A, C, S)``, average bf ``(A, C)``,
    the chosen candidates per target (``best_db1``, ``ten_db1``, ... as condition indices),
    the Table II rows per target ``(rows, A)`` and their avg/min/max ``(rows, 3)``, and the
    threshold study (paper Fig. 12).
    """
    acc, sizes = np.asarray(res["acc"], dtype=float), [int(s) for s in res["sizes"]]
    actions = [str(a) for a in res["actions"]]
    a = len(actions)
    lay = layout(a, len(cfg.thresholds))
    mean, sem = curves(acc)  # (A, C, S)
    bf = bootstrap_factor(mean, mean[:, lay["NB"]][:, None, :], cfg.chance)  # (A, C, S)
    avg = average_bf(bf, sizes, *cfg.bf_sizes)  # (A, C)
    t_idx = np.arange(a)
    lo, hi = cfg.best_sizes
    out: dict[str, Any] = {"actions": actions, "sizes": sizes, "mean": mean, "sem": sem, "bf": bf, "avg_bf": avg,
                           "conditions": [str(c) for c in res["conditions"]]}
    rows: dict[str, np.ndarray] = {"NB": avg[:, lay["NB"]]}
    for fam in ("DB1", "CB1"):
        idx = lay[fam]
        fam_mean = mean[:, idx]  # (A, K, S)
        best = idx[select_best(fam_mean, sizes, lo, hi)]
        ten = idx[select_at(fam_mean, sizes, cfg.select_size)] if cfg.select_size in sizes else best
        ran = np.any(np.isfinite(fam_mean), axis=-1)  # (A, K)
        with _quiet():
            rows[f"{fam} average"] = np.nanmean(np.where(ran, avg[:, idx], np.nan), axis=1)
        rows[f"{fam} best"] = np.where(ran.any(1), avg[t_idx, best], np.nan)
        rows[f"{fam} best after ten"] = np.where(ran.any(1), avg[t_idx, ten], np.nan)
        out[f"best_{fam.lower()}"], out[f"ten_{fam.lower()}"] = best, ten
        if fam == "DB1":
            rows["DBn"] = avg[:, lay["DBn"]]
        else:
            rows["CBn"] = avg[:, lay["CBn"][list(cfg.thresholds).index(cfg.cbn_threshold)]]
    per_target = np.stack([rows[r] for r in TABLE2_ROWS])  # (rows, A)
    with _quiet():
        summary = np.stack([np.nanmean(per_target, 1), np.nanmin(per_target, 1), np.nanmax(per_target, 1)], axis=1)
    out["table2_rows"] = list(TABLE2_ROWS)
    out["table2_per_target"] = per_target
    out["table2"] = summary
    out["thresholds"] = threshold_study(mean, bf, np.asarray(res["category_masks"], dtype=bool), sizes, cfg, lay)
    return out


def threshold_study(mean: np.ndarray, bf: np.ndarray, masks: np.ndarray, sizes: Sequence[int],
                    cfg: ExperimentConfig, lay: dict) -> dict[str, Any]:
    """Paper Fig. 12: per threshold T the bf curve ``(S,)`` of each target's best category
    among those built at T (mean over targets), plus the overall average over all usable
    categories; ``masks: (T, A, K)``."""
    idx = lay["CB1"]
    cb_mean, cb_bf = mean[:, idx], bf[:, idx]  # (A, K, S)
    ran = np.any(np.isfinite(cb_mean), axis=-1)  # (A, K)
    t_idx = np.arange(mean.shape[0])
    out: dict[str, Any] = {"T": list(cfg.thresholds), "best_curve": [], "count": [], "best": []}
    with _quiet():
        for ti in range(len(cfg.thresholds)):
            m = masks[ti] & ran  # (A, K)
            best = select_best(np.where(m[..., None], cb_mean, np.nan), sizes, *cfg.best_sizes)
            curve = np.where(m.any(1)[:, None], cb_bf[t_idx, best], np.nan)  # (A, S)
            out["best_curve"].append(np.nanmean(curve, axis=0))
            out["best"].append(idx[best])
            out["count"].append(int(masks[ti].any(0).sum()))
        out["overall_curve"] = np.nanmean(np.where(ran[..., None], cb_bf, np.nan), axis=(0, 1))
    out["best_curve"] = np.stack(out["best_curve"])
    return out


def categories_per_threshold(corr: np.ndarray, thresholds: Sequence[float]) -> dict[str, int]:
    """How many of the A(A-1)/2 categories the heuristic builds at each T (and how many pairs
    literally have corr > T, which differs from the kept count only at T <= 0)."""
    pairs = category_pairs(range(corr.shape[0]))
    i, j = np.asarray(pairs).T
    return {f"{t:g}": {"built": int(categories_above(corr, pairs, t).sum()), "corr_above": int((corr[i, j] > t).sum())}
            for t in thresholds}


# --------------------------------------------------------------------------------- CLI


def _parse_set(items: Iterable[str]) -> dict[str, Any]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            v = json.loads(value)
        except json.JSONDecodeError:
            v = value
        out[key.strip()] = tuple(v) if isinstance(v, list) else v
    return out


def _cmd_experiment(args: argparse.Namespace) -> int:
    cfg = override(preset(args.preset), _parse_set(args.set or []))
    spaces = list(SPACES) if args.space == "both" else [args.space]
    if args.synthetic and args.data:
        raise ValueError("give either --data or --synthetic, not both")
    if args.synthetic:
        datasets, desc = synthetic_datasets(args.synthetic, seed=args.seed), [f"synthetic:{args.synthetic}"]
    elif args.data:
        datasets, desc = load_datasets(args.data), list(args.data)
    else:
        raise ValueError("give --data DIR... (one featured dataset per action) or --synthetic N")
    jobs = args.jobs if args.jobs and args.jobs > 0 else (os.cpu_count() or 1)
    paths = run_experiment(datasets, args.out, cfg, spaces, seed=args.seed, jobs=jobs,
                           progress=not args.no_progress, data_desc=desc)
    for space, p in paths.items():
        print(f"{space}: {p}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from relaff_jax.report.report import write_report

    out = write_report(args.results, args.out)
    print(f"report: {out}")
    return 0


def register_cli(subparsers) -> None:
    """Add ``relaff experiment`` and ``relaff report``."""
    p = subparsers.add_parser("experiment", help="learning curves and bootstrapping sweeps (paper section V)",
                              description=__doc__.split("\n\n")[0])
    p.add_argument("--data", nargs="+", metavar="DIR", help="featured dataset folders, one per action")
    p.add_argument("--synthetic", type=int, metavar="N", default=0,
                   help="use N synthetic samples per action instead of --data (a dry run of the stage)")
    p.add_argument("--out", required=True, metavar="RESULTS", help="results folder (resumed if it exists)")
    p.add_argument("--preset", choices=("quick", "paper"), default="quick")
    p.add_argument("--space", choices=("pca", "rhf", "both"), default="both")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=0, help="worker processes (default: all cores)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a config field, e.g. --set reps_pca=5 --set 'sizes=[2,10,25]'")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_cmd_experiment)
    r = subparsers.add_parser("report", help="Table II and figures from an experiment folder")
    r.add_argument("results", metavar="RESULTS")
    r.add_argument("--out", required=True, metavar="REPORT")
    r.set_defaults(func=_cmd_report)
