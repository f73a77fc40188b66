"""The compiled forest engine's Python side: inputs checked and packed, one kernel call for
many forests, and the fitted forests as node arrays.

Takes forests to fit as ``X: (N, D)`` float32 finite states, ``y: (N,)`` labels and seeds;
``fit_many`` gives one ``Forest`` each, the trees of ``RandomForestClassifier(random_state=
seed)`` with the settings of ``ForestConfig`` (``build.py``); ``fit`` is one forest.
Takes fitted forests and test rows ``X: (N, D)`` (or shared columns ``ZT: (Dz, N)``); gives
``predict_proba`` ``(N, K)`` float64 and labels, bit-identical to scikit-learn's
(``evaluate.py``), many forests per call (``predict_block``).
"""
from __future__ import annotations

import dataclasses
import numbers
from typing import Sequence

import numpy as np

from relaff_jax.learn.forest.fit import check_engine_config, max_features_of, n_bootstrap
from relaff_jax.config.experiment import ForestConfig
from relaff_jax.learn.forest.estimator import checked_states, n_trees, subsample_size

MAX_DEPTH = np.iinfo(np.int32).max  # max_depth=None, as BaseDecisionTree._fit
SEED_LIMIT = 2**32  # RandomState seeds are in [0, 2**32)


@dataclasses.dataclass
class Forest:
    """One fitted forest as node arrays, T trees of M nodes in all.

    ``feature: (M,)`` int32 (-2 at leaves), ``threshold: (M,)`` float64 (-2.0 at leaves),
    ``left, right: (M,)`` int32 child ids local to the tree (-1 at leaves), ``value: (M, K)``
    float64 class fractions, ``tree_start: (T + 1,)`` int64 each tree's first node,
    ``classes: (K,)`` the sorted distinct labels, ``n_features`` D. Tree t's nodes are
    ``tree_start[t]:tree_start[t + 1]``, equal to ``estimators_[t].tree_`` arrays.
    """

    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    value: np.ndarray
    tree_start: np.ndarray
    classes: np.ndarray
    n_features: int

    @property
    def n_trees(self) -> int:
        return len(self.tree_start) - 1

    def tree(self, t: int) -> dict[str, np.ndarray]:
        """Tree t's arrays under ``sklearn.tree._tree.Tree``'s names (value ``(M_t, 1, K)``)."""
        a, b = self.tree_start[t], self.tree_start[t + 1]
        return dict(feature=self.feature[a:b], threshold=self.threshold[a:b], children_left=self.left[a:b],
                    children_right=self.right[a:b], value=self.value[a:b, None, :], node_count=b - a)


_KERNELS: dict = {}  # numba is imported (and the kernels loaded or compiled) on first use
SOURCES = ("rng.py", "split.py", "build.py", "evaluate.py")


def kernels() -> dict:
    """The compiled kernels, imported on first call: numba compiles them then (~30-40 s on
    two shared cores) or loads them from its on-disk cache (``cache=True``, in
    ``__pycache__`` next to the sources, or ``NUMBA_CACHE_DIR``). numba keys a function's
    cache on its own file only, and the kernels call across files, so a stamp of all four
    sources clears the cache when any of them changed (a development concern only)."""
    if not _KERNELS:
        _clear_stale_cache()
        # numba loads (and compiles) on the first call, not with the package
        from relaff_jax.learn.forest.compiled import build, evaluate

        _KERNELS.update(build_forests=build.build_forests, block_sums=evaluate.block_sums)
    return _KERNELS


def _clear_stale_cache() -> None:
    import hashlib
    from pathlib import Path

    here = Path(__file__).parent
    cache = here / "__pycache__"
    digest = hashlib.sha256(b"".join((here / f).read_bytes() for f in SOURCES)).hexdigest()
    stamp = cache / "compiled.stamp"
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for f in cache.glob("*.nb[ci]"):
            f.unlink()
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # a read-only install: its sources do not change either
        pass


def _settings(cfg: ForestConfig, n: int) -> tuple[int, int, int]:
    """(min_samples_leaf, min_samples_split, max_depth) as ``BaseDecisionTree._fit`` resolves them."""
    msl = cfg.min_samples_leaf
    msl = int(msl) if isinstance(msl, numbers.Integral) else int(np.ceil(msl * n))
    return msl, max(2, 2 * msl), MAX_DEPTH if cfg.max_depth is None else int(cfg.max_depth)


def fit_many(Xs: Sequence[np.ndarray], ys: Sequence[np.ndarray], seeds: Sequence[int],
             cfg: ForestConfig = ForestConfig()) -> list[Forest]:
    """F forests in one kernel call: ``Xs[f]: (N_f, D_f)`` finite, ``ys[f]: (N_f,)``, ``seeds[f]``
    in [0, 2**32). Forests of one call must share ``min_samples_leaf``'s resolved value (an
    integer ``min_samples_leaf``, the default, always does)."""
    check_engine_config(cfg)
    if not len(Xs) == len(ys) == len(seeds):
        raise ValueError(f"fit_many: {len(Xs)} X, {len(ys)} y and {len(seeds)} seeds")
    if not Xs:
        return []
    F = len(Xs)
    ns = np.empty(F, np.int64)
    ds = np.empty(F, np.int64)
    ks = np.empty(F, np.int64)
    nt = np.empty(F, np.int64)
    nb = np.empty(F, np.int64)
    mf = np.empty(F, np.int64)
    xs, codes, classes, msls = [], [], [], set()
    per_shape: dict[tuple[int, int], tuple] = {}  # (N, D) -> trees, max features, draws, settings
    for f, (X, y, s) in enumerate(zip(Xs, ys, seeds)):
        X = np.asarray(X, dtype=np.float32)
        y = np.asarray(y)
        if X.ndim != 2 or y.shape != (X.shape[0],) or X.shape[0] < 1:
            raise ValueError(f"fit_many: forest {f}: X must be (N, D) with N >= 1 and y (N,), got {X.shape} and {y.shape}")
        if not 0 <= int(s) < SEED_LIMIT:
            raise ValueError(f"fit_many: forest {f}: seed {s} is not in [0, 2**32)")
        n, d = X.shape
        c, enc = _bool_classes(y) if y.dtype == np.bool_ else np.unique(y, return_inverse=True)
        if len(c) > 2:
            raise ValueError(f"fit_many: forest {f}: {len(c)} classes, the compiled engine builds binary forests")
        shape = per_shape.get((n, d))
        if shape is None:
            m = max_features_of(d, cfg)
            if not 0 < m <= d:
                raise ValueError("max_features must be in (0, n_features]")
            draws = subsample_size(n) if cfg.per_tree == "subsample" else n_bootstrap(n, cfg) if cfg.bootstrap else n
            shape = per_shape[n, d] = (n_trees(n, cfg), m, draws, _settings(cfg, n))
        ns[f], ds[f], ks[f], (nt[f], mf[f], nb[f], settings) = n, d, len(c), shape
        xs.append(X.T.ravel())  # features by row
        codes.append(enc.reshape(-1))
        classes.append(c)
        msls.add(settings)
    if len(msls) > 1:
        raise ValueError("fit_many: forests of one call must resolve min_samples_leaf alike (call per size)")
    msl, min_split, max_depth = msls.pop()
    x_start = np.concatenate([[0], np.cumsum(ns * ds)]).astype(np.int64)
    xs = np.concatenate(xs).astype(np.float32, copy=False)
    if not np.all(np.isfinite(xs)):
        raise ValueError("fit_many: X contains NaN or inf")
    feat, thr, left, right, value, starts = kernels()["build_forests"](
        xs, x_start, ns, ds, np.concatenate(codes).astype(np.int64), ks, np.asarray(seeds, np.int64), nt, nb, mf,
        msl, min_split, max_depth, 2 if cfg.per_tree == "subsample" else int(bool(cfg.bootstrap)))
    out, t0 = [], 0
    for f in range(F):
        ts = starts[t0: t0 + nt[f] + 1]
        a, b = ts[0], ts[-1]
        out.append(Forest(feat[a:b], thr[a:b], left[a:b], right[a:b], value[a:b, : ks[f]], ts - a, classes[f], int(ds[f])))
        t0 += nt[f]
    return out


def _bool_classes(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(y, return_inverse=True)`` of bool labels ``y: (N,)`` without sorting: the
    distinct labels (bool, ascending) and each sample's class code (0/1; bool here, the
    codes are cast to int64 with the others)."""
    k = int(np.count_nonzero(y))
    if 0 < k < len(y):
        return np.array([False, True]), y
    return np.array([k > 0]), np.zeros(len(y), bool)


def fit(X: np.ndarray, y: np.ndarray, seed: int, cfg: ForestConfig = ForestConfig()) -> Forest:
    """One forest (``fit_many`` of one)."""
    return fit_many([X], [y], [seed], cfg)[0]


def _columns(X: np.ndarray, n_features: int, who: str) -> np.ndarray:
    return np.ascontiguousarray(checked_states(X, who, n_features).T)


def predict_proba(forest: Forest, X: np.ndarray) -> np.ndarray:
    """``(N, K)`` float64, bit-identical to ``RandomForestClassifier.predict_proba``; ``X: (N, D)``."""
    s = _sums([forest], _columns(X, forest.n_features, "predict_proba"), [np.arange(forest.n_features)])[0]
    return s[: len(forest.classes)].T / forest.n_trees


def predict_labels(forest: Forest, X: np.ndarray) -> np.ndarray:
    """Predicted labels ``(N,)`` (the training labels' dtype), as ``predict``."""
    return forest.classes.take(np.argmax(predict_proba(forest, X), axis=1), axis=0)


def predict_block(forests: Sequence[Forest], ZT: np.ndarray, colmaps: Sequence[np.ndarray]) -> np.ndarray:
    """Predicted labels ``(F, N)`` of F forests on the N columns of ``ZT: (Dz, N)`` float32
    (finite where referenced); ``colmaps[f]: (D_f,)`` forest f's features as rows of ``ZT``.
    One kernel call; the same labels as each forest's ``predict``."""
    ZT = np.ascontiguousarray(ZT, dtype=np.float32)
    if not forests:
        return np.zeros((0, ZT.shape[1]))
    s = _sums(forests, ZT, colmaps)
    out = []
    for f, sf in zip(forests, s):
        T = float(f.n_trees)
        code = (sf[1] / T > sf[0] / T) if len(f.classes) > 1 else np.zeros(sf.shape[1], bool)
        out.append(f.classes.take(code.astype(np.intp)))
    return np.stack(out)


def _sums(forests: Sequence[Forest], ZT: np.ndarray, colmaps: Sequence[np.ndarray]) -> np.ndarray:
    """``(F, 2, N)`` per-forest leaf-value sums in tree order (``evaluate.block_sums``)."""
    counts = np.asarray([f.n_trees for f in forests])
    node0 = np.concatenate([[0], np.cumsum([len(f.feature) for f in forests])])
    tree_start = np.concatenate([forests[0].tree_start[:1]] + [f.tree_start[1:] + o for f, o in zip(forests, node0)])
    cm = [np.asarray(c, dtype=np.int64) for c in colmaps]
    return kernels()["block_sums"](
        np.concatenate([f.feature for f in forests]), np.concatenate([f.threshold for f in forests]),
        np.concatenate([f.left for f in forests]), np.concatenate([f.right for f in forests]),
        np.concatenate([_value2(f) for f in forests]), tree_start.astype(np.int64),
        np.concatenate([[0], np.cumsum(counts)]).astype(np.int64), np.concatenate(cm),
        np.concatenate([[0], np.cumsum([len(c) for c in cm])]).astype(np.int64), ZT)


def _value2(forest: Forest) -> np.ndarray:
    """``value`` as ``(M, 2)`` (a forest of one class gets a zero second column)."""
    v = forest.value
    return v if v.shape[1] == 2 else np.concatenate([v, np.zeros_like(v)], axis=1)


def warm(cfg: ForestConfig = ForestConfig()) -> None:
    """Load the kernels, or compile them into numba's cache (a new install: ~30-40 s), by
    fitting and evaluating one small forest of ``cfg`` (the argument types of every call, so
    later processes load what this one compiled). ``reproduce`` runs it in a process of its own
    during the generate stage (``stages/audits.py``), so the experiment's workers load the cache
    instead of each compiling the same kernels."""
    rng = np.random.default_rng(0)
    X = rng.random((40, 3), dtype=np.float32)
    y = X[:, 0] > 0.5  # bool, as the experiment passes them (estimator.checked_inputs)
    predict_block(fit_many([X], [y], [0], cfg), X.T, [np.arange(3)])
