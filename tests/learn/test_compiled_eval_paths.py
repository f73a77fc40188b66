"""The compiled engine's evaluation (learn/forest/compiled/evaluate.py) against a numpy oracle of
scikit-learn's summation: every path (one leaf, <= 32 leaves with float32 compares, <= 64,
the node walk; forests of pure leaves counted as integer votes, others summed in tree
order) gives the same float64 sums, bit for bit, on rows placed at the thresholds' float32
neighbours."""
import numpy as np
import pytest

from relaff_jax.learn.forest import compiled
from relaff_jax.learn.forest.compiled import forest as cf
from relaff_jax.learn.forest.evaluate import round_down_f32


def oracle_sums(forest: compiled.Forest, ZT: np.ndarray, colmap: np.ndarray) -> np.ndarray:
    """``(2, N)``: each tree's exit leaf by ``float64(x) <= threshold`` (``Tree.apply``), its
    value added into float64 zeros in tree order (``ForestClassifier.predict_proba``)."""
    n = ZT.shape[1]
    out = np.zeros((2, n))
    v = forest.value if forest.value.shape[1] == 2 else np.concatenate([forest.value, np.zeros_like(forest.value)], 1)
    rows = np.arange(n)
    for t in range(forest.n_trees):
        a = forest.tree_start[t]
        node = np.zeros(n, np.int64)
        while True:
            g = a + node
            inner = forest.left[g] != -1
            if not inner.any():
                break
            x = ZT[colmap[np.maximum(forest.feature[g], 0)], rows].astype(np.float64)
            go_left = x <= forest.threshold[g]
            node = np.where(inner, np.where(go_left, forest.left[g], forest.right[g]), node)
        out += v[a + node].T
    return out


def _rows(forest: compiled.Forest, d: int, rng) -> np.ndarray:
    """``(d, N)`` float32 test columns: random rows, and for a sample of the internal nodes
    a row at the threshold's float32 below (goes left) and the next float32 (goes right)."""
    base = rng.normal(size=(200, d)).astype(np.float32)
    inner = np.flatnonzero(forest.left != -1)
    pick = rng.choice(inner, size=min(len(inner), 300), replace=False) if len(inner) else inner
    t32 = round_down_f32(forest.threshold[pick])
    edge = np.repeat(base[:1], 2 * len(pick), axis=0)
    edge[np.arange(len(pick)) * 2, forest.feature[pick]] = t32
    edge[np.arange(len(pick)) * 2 + 1, forest.feature[pick]] = np.nextafter(t32, np.float32(np.inf))
    return np.ascontiguousarray(np.concatenate([base, edge]).T)


def _case(kind: str, n: int, d: int, rng):
    X = rng.normal(size=(n, d)).astype(np.float32)
    if kind == "one_class":
        y = np.ones(n, bool)
    elif kind == "noise":  # deep trees: > 32 and > 64 leaves
        y = rng.random(n) < 0.5
    else:
        y = X[:, 0] + 0.4 * rng.normal(size=n) > 0
    if kind == "impure":  # repeated rows with the other label: impure leaves
        k = max(1, n // 4)
        X[-k:] = X[:k]
        y[-k:] = ~y[:k]
    return X, y


@pytest.mark.parametrize("kind,n,d", [("plain", 2, 3), ("plain", 12, 5), ("plain", 40, 18), ("impure", 9, 4),
                                      ("impure", 60, 6), ("one_class", 10, 3), ("noise", 90, 4),
                                      ("noise", 260, 5)])
def test_sums_equal_the_tree_order_oracle(kind, n, d):
    rng = np.random.default_rng(n * 31 + d)
    X, y = _case(kind, n, d, rng)
    forest = compiled.fit(X, y, int(rng.integers(2**32)))
    ZT = _rows(forest, d, rng)
    got = cf._sums([forest], ZT, [np.arange(d)])[0]
    want = oracle_sums(forest, ZT, np.arange(d))
    assert got.dtype == want.dtype and np.array_equal(got[: 2], want)
    leaves = np.diff(forest.tree_start) - np.add.reduceat(forest.left != -1, forest.tree_start[:-1])
    if kind == "noise" and n > 200:  # the 64-bit path and the node walk
        assert leaves.max() > 64 and ((leaves > 32) & (leaves <= 64)).any()
    if kind == "plain" and n > 20:  # the 32-bit path
        assert ((leaves > 1) & (leaves <= 32)).all()
    if kind == "impure":  # the tree-order path, not the vote counts
        lv = forest.value[forest.left == -1]
        assert not np.all((lv == 0.0) | (lv == 1.0))


def test_block_of_mixed_forests_on_shared_columns():
    """Pure and impure forests, one class and deep ones, in one call with column maps."""
    rng = np.random.default_rng(7)
    cases = [("plain", 30, 4), ("impure", 30, 4), ("one_class", 5, 4), ("noise", 150, 4), ("plain", 2, 4)]
    forests, maps = [], []
    for kind, n, d in cases:
        X, y = _case(kind, n, d, rng)
        forests.append(compiled.fit(X, y, int(rng.integers(2**32))))
        maps.append(rng.permutation(6)[:d])  # forest features read rows of ZT in another order
    ZT = rng.normal(size=(6, 300)).astype(np.float32)
    got = cf._sums(forests, ZT, maps)
    for f, m, g in zip(forests, maps, got):
        assert np.array_equal(g, oracle_sums(f, ZT, m))
