"""The four experiments of paper section VI on relation data (beside = 0 vs on_top = 1).

Takes real data ``{pca (Nr, 18), rhf (Nr, 300), y (Nr,)}`` (``real_data``) and simulated
data ``{pca (Ns, 18), rhf (Ns, 300), relation (Ns,)}`` (``sim_relations``; ``inside`` scenes
are left out here) and a ``RealExperimentConfig``; ``run_space(real, sim, space, cfg)`` gives,
for one state space (``pca``: 18 values; ``rhf``: 318 = PCA + RHF, as ``learn.states``),
accuracies over ``reps`` repetitions:

1. SIM -> SIM: ``sim_fair (R,)`` trained on as many balanced sim samples as the real training
   set, ``sim_full (R,)`` on ``n_full``; each tested on as many other balanced sim samples;
2. REAL -> REAL: ``real (R,)``: within one folder a balanced train / test split per repetition
   (``splits``; ``cfg.split`` "scene": every pair of a scene on one side, the default; "pair":
   pairs drawn one by one), ``train_fraction`` of the balanced pool to train (the paper's 100
   of 160); with ``test`` (another folder) trained on the whole first folder (balanced) and
   tested on every pair of ``test``;
3. SIM -> REAL: ``fair_to_real``, ``full_to_real (R,)``: the same sim forests on every real
   pair (of ``test`` when given). Every real test is scored by balanced accuracy (mean of the
   two per-class accuracies; chance 0.5; equal to the accuracy on a balanced test set), so an
   unbalanced real pool counts as a balanced test set;
4. REAL <- SIM: ``curve_sl``, ``curve_bl (S, R)`` over training sizes ``sizes`` (S,): the real
   learner without / with the SIM_full forest's 0/1 prediction as a bootstrap input repeated
   ``repeats[space]`` times (``learn.states.augment``), trained on the first n of the
   repetition's training split in alternating class order, tested on its test split (on
   ``test`` across folders). ``kind`` says which split made the figures ("scene", "pair",
   "cross"), ``test_counts`` the real test set per class (beside, on_top).

``run_sim_only(sim, space, cfg)`` adds SIM -> SIM for each pair of the three relations
(``inside`` exists in simulation only). Forests: the project's engine (``learn.engine``) with 100 trees for every training size
(paper VI-A). Seeds: ``derive_seed(seed, 17, space, rep, experiment, n)``.
``summarise`` gives mean, std and a percentile bootstrap interval over repetitions, and the
bootstrap factor curve with the count of sizes where it is undefined (P_sl <= 0.5) and an
interval of its mean over the window ``cfg.bf_sizes`` of training sizes (repetitions
resampled), the paired differences the claims are decided on (``differences``) and the
per-pair error table (``pair_errors``).
"""
from __future__ import annotations

import numpy as np

from relaff_jax.constants import BESIDE, ON_TOP, RELATIONS, SPACES
from relaff_jax.errors import UserError
from relaff_jax.learn.analysis import bootstrap_factor
from relaff_jax.learn.forest.engine import fit, predict
from relaff_jax.learn.states import augment, state_features
from relaff_jax.data.progress import progress_bar
from relaff_jax.provenance import derive_seed

from . import paired, splits
from .paired import HITS, _balanced, interval, scene_resamples  # noqa: F401  (the protocol's helpers, re-exported)
from relaff_jax.config.real import RealExperimentConfig
from .splits import balanced_take, split_sizes  # noqa: F401  (re-exported: the experiments' protocol)
from relaff_jax.config import streams


def states(data: dict, space: str) -> np.ndarray:
    """(N, 18) PCA or (N, 318) PCA + RHF states, float32."""
    if space not in SPACES:
        raise UserError(f"unknown space {space!r}; valid: {', '.join(SPACES)}")
    return state_features(data["pca"], data["rhf"] if space == "rhf" else None, None, space)


def balanced_accuracy(pred: np.ndarray, y: np.ndarray) -> float:
    """Mean of the per-class accuracies (0.5 = chance)."""
    y = np.asarray(y).astype(bool)
    pred = np.asarray(pred) > 0.5
    return float(np.mean([np.mean(pred[y] == y[y]), np.mean(pred[~y] == y[~y])]))


def run_space(real: dict, sim: dict, space: str, cfg: RealExperimentConfig = RealExperimentConfig(),
              progress: bool = False, test: dict | None = None) -> dict:
    """The four experiments in one space (see the module docstring); arrays keyed by name.
    ``test``: another folder's pairs (``real_data.real_features``): then REAL trains on the
    whole of ``real`` (balanced, ``splits.train_pool``) and every classifier is scored on ``test``."""
    Xr, yr = states(real, space), np.asarray(real["y"]).astype(bool)
    Xt, yt = (Xr, yr) if test is None else (states(test, space), np.asarray(test["y"]).astype(bool))
    if min(yt.sum(), (~yt).sum()) < 1:
        raise UserError(f"the test folder needs >= 1 pair of each relation, have {int((~yt).sum())} beside "
                        f"and {int(yt.sum())} on_top")
    keep = np.isin(sim["relation"], [BESIDE, ON_TOP])
    Xs, ys = states(sim, space)[keep], np.asarray(sim["relation"])[keep] == ON_TOP
    code = SPACES.index(space)
    kind = "cross" if test is not None else cfg.split
    if kind == "cross":
        sz = dict(pool=int(min(yr.sum(), (~yr).sum())), test=int(len(yt)))
        sz["train"] = sz["pool"]
    else:
        sz = splits.split_sizes(yr, cfg.train_fraction)
    if kind == "scene":  # drawn first, on their own seeds: every repetition must share n_train
        grouped, sz["train"] = splits.scene_splits(yr, real["scene"], sz, cfg.seed, cfg.reps, code)
    n_tr, n_fair = sz["train"], 2 * sz["train"]
    sim0, sim1 = np.flatnonzero(~ys), np.flatnonzero(ys)
    half_full = cfg.n_full // 2
    if min(len(sim0), len(sim1)) < 2 * half_full:
        raise UserError(f"SIM_full needs {2 * half_full} simulated scenes of each relation (train + test), "
                        f"have {len(sim0)} beside and {len(sim1)} on_top: simulate more or lower n_full")
    sizes = np.arange(2, 2 * n_tr + 1)
    fcfg, rep = cfg.forest(), cfg.repeats(space)
    out = {k: np.zeros(cfg.reps) for k in ("sim_fair", "sim_full", "real", "fair_to_real", "full_to_real")}
    out["curve_sl"] = np.zeros((len(sizes), cfg.reps))
    out["curve_bl"] = np.zeros((len(sizes), cfg.reps))
    # per real test pair and repetition: 1 right, 0 wrong, NaN not tested (the per-pair error table)
    for k in HITS:
        out[f"pairs_{k}"] = np.full((cfg.reps, len(yt)), np.nan)
    if test is not None:  # per test pair and repetition: right or wrong (an interval over test scenes)
        for k in HITS:
            out[f"hits_{k}"] = np.zeros((cfg.reps, len(yt)), bool)
        out["hits_curve_sl"] = np.zeros((len(sizes), cfg.reps, len(yt)), bool)
        out["hits_curve_bl"] = np.zeros((len(sizes), cfg.reps, len(yt)), bool)
    bar = progress_bar(progress, cfg.reps, f"{space} experiments ({kind})", unit="rep")
    for r in range(cfg.reps):
        rng = np.random.default_rng(derive_seed(cfg.seed, streams.REAL_EXPERIMENT, code, r))
        # 1 + 3: simulation forests, tested in simulation and on every real test pair
        for name, n_half, e in (("fair", n_tr, 0), ("full", half_full, 1)):
            idx = balanced_take(rng, sim0, sim1, 2 * n_half)
            tr, te = idx[: 2 * n_half], idx[2 * n_half:]
            forest = fit(Xs[tr], ys[tr], derive_seed(cfg.seed, streams.REAL_EXPERIMENT, code, r, e), fcfg)
            out[f"sim_{name}"][r] = float(np.mean(predict(forest, Xs[te]) == ys[te]))
            pred_t = predict(forest, Xt)
            out[f"{name}_to_real"][r] = balanced_accuracy(pred_t, yt)
            out[f"pairs_{name}_to_real"][r] = (np.asarray(pred_t) > 0.5) == yt
            if test is not None:
                out[f"hits_{name}_to_real"][r] = (np.asarray(pred_t) > 0.5) == yt
            if name == "full":  # the bootstrap input, on the training pairs and on the test pairs
                boot_r, boot_t = (pred_t, pred_t) if test is None else (predict(forest, Xr), pred_t)
        # 2: real forests; within a folder on a split of it, across folders on the whole train folder
        if kind == "pair":
            tr, te = splits.pair_split(rng, yr, sz)
        elif kind == "scene":
            tr, te = grouped[r]
        else:
            tr, te = splits.train_pool(rng, yr), None
        Xte, yte = (Xr[te], yr[te]) if te is not None else (Xt, yt)
        forest = fit(Xr[tr], yr[tr], derive_seed(cfg.seed, streams.REAL_EXPERIMENT, code, r, 2), fcfg)
        pred = predict(forest, Xte)
        out["real"][r] = balanced_accuracy(pred, yte)
        out["pairs_real"][r, slice(None) if te is None else te] = (np.asarray(pred) > 0.5) == yte
        if test is not None:
            out["hits_real"][r] = (np.asarray(pred) > 0.5) == yte
        # 4: learning curves without / with the SIM_full prediction
        Xb = augment(Xr, boot_r[None], rep)
        Xbt = Xb[te] if te is not None else augment(Xt, boot_t[None], rep)
        for s, n in enumerate(sizes):
            sub = tr[:n]
            f_sl = fit(Xr[sub], yr[sub], derive_seed(cfg.seed, streams.REAL_EXPERIMENT, code, r, 3, n), fcfg)
            f_bl = fit(Xb[sub], yr[sub], derive_seed(cfg.seed, streams.REAL_EXPERIMENT, code, r, 4, n), fcfg)
            p_sl, p_bl = predict(f_sl, Xte), predict(f_bl, Xbt)
            out["curve_sl"][s, r] = balanced_accuracy(p_sl, yte)
            out["curve_bl"][s, r] = balanced_accuracy(p_bl, yte)
            if test is not None:
                out["hits_curve_sl"][s, r] = (np.asarray(p_sl) > 0.5) == yte
                out["hits_curve_bl"][s, r] = (np.asarray(p_bl) > 0.5) == yte
        bar.update(1)
    bar.close()
    out["sizes"] = sizes
    out["split"] = np.asarray([sz["pool"], sz["train"], sz["test"], n_fair, 2 * half_full])
    out["kind"] = np.asarray(kind)
    out["test_counts"] = np.asarray([int((~yte).sum()), int(yte.sum())])
    if test is not None:
        out["test_y"], out["test_scene"] = yt, np.asarray(test["scene"]).astype(str)
    tdata = real if test is None else test  # the pairs the per-pair arrays' columns are
    out["pairs_scene"] = np.asarray(tdata["scene"]).astype(str)
    out["pairs_ab"] = np.asarray([f"{a},{b}" for a, b in zip(tdata.get("a", [""] * len(yt)), tdata.get("b", [""] * len(yt)))])
    out["pairs_y"] = yt
    return out


def _central_95(vals: list, n_boot: int) -> tuple[float, float] | None:
    """The 2.5 and 97.5 percentiles of the resampled bf means; None when bf was undefined in
    at least half of the ``n_boot`` resamples (the interval would describe a minority)."""
    if len(vals) < n_boot / 2:
        return None
    lo, hi = np.quantile(vals, [0.025, 0.975])
    return float(lo), float(hi)


def bf_scene_interval(res: dict, early: np.ndarray, rng: np.random.Generator,
                      n_boot: int) -> tuple[float, float] | None:
    """95 % interval of the early mean bootstrap factor across folders with the test scenes
    resampled (``scene_resamples``), the curves' per-pair hits averaged over repetitions."""
    y = np.asarray(res["test_y"]).astype(bool)
    sl, bl = np.asarray(res["hits_curve_sl"], float).mean(1), np.asarray(res["hits_curve_bl"], float).mean(1)  # (S, N)
    vals = []
    for idx in scene_resamples(y, res["test_scene"], rng, n_boot):
        bf = bootstrap_factor(_balanced(bl[:, idx], y[idx]), _balanced(sl[:, idx], y[idx]))[early]
        if np.isfinite(bf).any():
            vals.append(np.nanmean(bf))
    return _central_95(vals, n_boot)


def scene_interval(hits: np.ndarray, y: np.ndarray, scene: np.ndarray, rng: np.random.Generator,
                   n_boot: int, level: float = 0.95) -> tuple[float, float] | None:
    """Percentile interval of a cross-folder balanced accuracy when the *test scenes* are
    resampled (with replacement, whole scenes: pairs of a scene are not independent) on top of
    the repetitions: ``hits (R, N)`` right/wrong per repetition and test pair, ``y``, ``scene``
    (N,). It says how far another folder of such scenes may land; the interval over
    repetitions alone (``interval``) only says how well the mean over forests is known.
    Resamples without both relations are drawn again; None if most are."""
    y = np.asarray(y).astype(bool)
    per_pair = np.asarray(hits, float).mean(axis=0)  # (N,) mean over repetitions
    vals = [_balanced(per_pair[idx], y[idx]) for idx in scene_resamples(y, scene, rng, n_boot)]
    if len(vals) < n_boot / 2:
        return None
    lo, hi = np.quantile(vals, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


SIM_PAIRS = (("beside", "on_top"), ("beside", "inside"), ("on_top", "inside"))


def run_sim_only(sim: dict, space: str, cfg: RealExperimentConfig = RealExperimentConfig()) -> dict:
    """SIM -> SIM for every pair of relations, ``inside`` included (no real data has it):
    ``{"a_vs_b": (R,) accuracies}``, each forest trained on k balanced scenes per class and
    tested on k others, k = min(n_full / 2, half the smaller class)."""
    X, rel = states(sim, space), np.asarray(sim["relation"])
    code = SPACES.index(space)
    out = {}
    for p, (a, b) in enumerate(SIM_PAIRS):
        ia, ib = np.flatnonzero(rel == RELATIONS.index(a)), np.flatnonzero(rel == RELATIONS.index(b))
        k = min(cfg.n_full // 2, len(ia) // 2, len(ib) // 2)
        if k < 1:
            raise UserError(f"SIM -> SIM {a} vs {b} needs >= 2 simulated scenes of each, have {len(ia)}, {len(ib)}")
        acc = np.zeros(cfg.reps)
        for r in range(cfg.reps):
            rng = np.random.default_rng(derive_seed(cfg.seed, streams.SIM_TO_SIM, code, p, r))
            idx = balanced_take(rng, ia, ib, 2 * k)  # class 1 = b
            tr, te = idx[: 2 * k], idx[2 * k:]
            yb = rel == RELATIONS.index(b)
            forest = fit(X[tr], yb[tr], derive_seed(cfg.seed, streams.SIM_TO_SIM, code, p, r, 1), cfg.forest())
            acc[r] = float(np.mean(predict(forest, X[te]) == yb[te]))
        out[f"{a}_vs_{b}"] = acc
        out[f"{a}_vs_{b}_n"] = np.asarray(2 * k)
    return out


def _bf_interval(sl: np.ndarray, bl: np.ndarray, early: np.ndarray, rng: np.random.Generator,
                 n_boot: int) -> tuple[float, float] | None:
    """Percentile bootstrap interval (95 %) of the early mean bootstrap factor, resampling
    repetitions (the columns of the (S, R) curves); None when it is undefined in most resamples."""
    R = sl.shape[1]
    vals = []
    for _ in range(n_boot):
        i = rng.integers(0, R, R)
        bf = bootstrap_factor(bl[:, i].mean(1), sl[:, i].mean(1))[early]
        if np.isfinite(bf).any():
            vals.append(np.nanmean(bf))
    return _central_95(vals, n_boot)


def summarise(res: dict, cfg: RealExperimentConfig = RealExperimentConfig()) -> dict:
    """Mean, std (ddof=1) and 95 % bootstrap interval of each accuracy; curves, bootstrap
    factors per size and the sizes where bf is undefined (P_sl <= 0.5)."""
    rng = np.random.default_rng(derive_seed(cfg.seed, streams.REAL_EXPERIMENT, 9))
    acc = {}
    for k in ("sim_fair", "sim_full", "real", "fair_to_real", "full_to_real"):
        x = np.asarray(res[k])
        acc[k] = dict(mean=float(x.mean()), std=float(x.std(ddof=1)) if len(x) > 1 else 0.0,
                      ci95=interval(x, rng, cfg.n_boot))
        if f"hits_{k}" in res:
            acc[k]["ci95_scenes"] = scene_interval(res[f"hits_{k}"], res["test_y"], res["test_scene"], rng, cfg.n_boot)
    sl, bl = res["curve_sl"].mean(axis=1), res["curve_bl"].mean(axis=1)
    bf = bootstrap_factor(bl, sl)
    sizes = np.asarray(res["sizes"])
    undefined = sizes[~np.isfinite(bf)]
    early = (sizes >= cfg.bf_sizes[0]) & (sizes <= cfg.bf_sizes[1])  # the window in training sizes
    with np.errstate(invalid="ignore"):
        bf_early = float(np.nanmean(bf[early])) if np.isfinite(bf[early]).any() else float("nan")
    bf_ci = _bf_interval(res["curve_sl"], res["curve_bl"], early, rng, cfg.n_boot)
    bf_ci_scenes = bf_scene_interval(res, early, rng, cfg.n_boot) if "hits_curve_sl" in res else None
    sim_only = {k: dict(mean=float(np.mean(res[k])), std=float(np.std(res[k], ddof=1)) if len(res[k]) > 1 else 0.0,
                        ci95=interval(res[k], rng, cfg.n_boot), n_train=int(res[k + "_n"]))
                for k in (f"{a}_vs_{b}" for a, b in SIM_PAIRS) if k in res}
    pool, train, test, n_fair, n_full = (int(v) for v in res["split"])
    return dict(accuracy=acc, sizes=sizes.tolist(), curve_sl=sl.tolist(), curve_bl=bl.tolist(),
                curve_sl_std=res["curve_sl"].std(axis=1, ddof=1).tolist(),
                curve_bl_std=res["curve_bl"].std(axis=1, ddof=1).tolist(),
                bf=[None if not np.isfinite(v) else float(v) for v in bf],
                bf_undefined_sizes=undefined.tolist(), bf_early_sizes=sizes[early].tolist(), bf_early_mean=bf_early,
                bf_early_ci95=bf_ci, bf_early_ci95_scenes=bf_ci_scenes,
                split=dict(kind=str(res.get("kind", "pair")), real_pool_per_class=pool, real_train_per_class=train,
                           real_test=test, real_test_counts=[int(v) for v in res.get("test_counts", (test, test))],
                           sim_fair_train=n_fair, sim_full_train=n_full), reps=len(res["real"]),
                sim_only=sim_only, bf_window=list(cfg.bf_sizes), differences=paired.differences(res, rng, cfg.n_boot),
                pair_errors=paired.pair_errors(res))
