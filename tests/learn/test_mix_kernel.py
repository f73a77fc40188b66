"""``measures._mix``'s compiled weighted sum (``learn/mix_kernel.py``) against numpy's expression.

The values are random floats whose sums depend on their order, with zero, tied and NaN
weights and NaN cells; K from 1 to 36 covers the candidates' counts of the families, and
K >= 8 is where numpy's pairwise summation (its path when S == 1) would differ from one by one.
"""
import numpy as np
import pytest

from relaff_jax.learn.measures import _mix


def _case(rng, lead, a, k, s):
    cells = rng.normal(size=lead + (a, k, s)) * 10.0 ** rng.integers(-3, 4, size=lead + (a, k, s))
    cells[rng.random(cells.shape) < 0.05] = np.nan
    w = rng.random(lead + (a, k))
    w[rng.random(w.shape) < 0.3] = 0.0
    w[rng.random(w.shape) < 0.02] = np.nan
    w[..., :1, :] = 0.0  # a target whose every weight is 0: NaN
    return cells, w / np.maximum(np.nansum(w, -1, keepdims=True), 1e-300)


@pytest.mark.parametrize("lead,a,k,s", [((), 9, 8, 22), ((100,), 9, 36, 22), ((3, 4), 2, 9, 5),
                                        ((7,), 3, 1, 2), ((5,), 4, 13, 99), ((2,), 0, 4, 3)])
def test_kernel_gives_numpys_bits(lead, a, k, s):
    rng = np.random.default_rng(k * 100 + s)
    cells, w = _case(rng, lead, a, k, s)
    ref = _mix(cells, w, reference=True)
    got = _mix(cells, w)
    assert got.shape == ref.shape == lead + (a, s)
    assert got.tobytes() == ref.tobytes()
    # a non-contiguous view of the cells (as the analysis slices its families): the same bits
    big = np.concatenate([cells, cells], -2)[..., ::2, :] if k > 1 else cells
    assert _mix(big, np.concatenate([w, w], -1)[..., ::2]).tobytes() == \
        _mix(big, np.concatenate([w, w], -1)[..., ::2], reference=True).tobytes()


def test_order_matters_for_these_values():
    # the check above can fail: summed pairwise (numpy with one size column) the same cells differ
    rng = np.random.default_rng(1)
    cells, w = _case(rng, (200,), 9, 36, 2)
    one_by_one = _mix(cells, w)[..., :1]
    pairwise = _mix(cells[..., :1], w)  # S == 1: numpy's own path, pairwise over the 36
    finite = np.isfinite(one_by_one)
    assert finite.any() and not np.array_equal(one_by_one[finite], pairwise[finite])


def test_compiled_beside_the_generate_stage_into_numbas_cache(tmp_path, monkeypatch):
    # reproduce compiles the kernel in the generate stage's warm-up process (one process for
    # every such warm-up): it leaves the kernel in numba's cache for the report to load
    from relaff_jax.learn.measures import compile_mix_kernel
    from relaff_jax.stages import audits

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))  # the spawned process inherits it
    b = audits.Beside.__new__(audits.Beside)
    b.pool, b.process, b.warming = object(), None, []  # as on two cores, without a run
    b.warm_elsewhere(compile_mix_kernel)
    first = b.process
    b.warm_elsewhere(compile_mix_kernel)
    try:
        assert b.process is first and [f.result(120) for f in b.warming] == [None, None]
    finally:
        b.process.shutdown()
    assert any("mix_kernel.weighted_sums" in p.name and p.suffix == ".nbi" for p in tmp_path.rglob("*"))
