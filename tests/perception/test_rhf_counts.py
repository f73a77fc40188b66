"""The RHF counting loop (wrapped row tiles, one scatter of the joint indices per tile, scenes
one after another under vmap) against the loop it replaced (``rhf_histograms_fused``): the
same bits, single and batched, on random clouds with clipped values, empty objects and
capacities past C."""
import dataclasses

import jax
import numpy as np

import relaff_jax  # noqa: F401  (XLA flags before JAX)
from relaff_jax.config.perception import PerceptionConfig
from relaff_jax.perception.descriptors import rhf_histograms, rhf_histograms_fused

RCFG = dataclasses.replace(PerceptionConfig().rhf, chunk=32)


def clouds(seed, n, v=128):
    """n scenes of two clouds (V = v points each): points spread past the histogram ranges,
    unit normals, some exactly axis-aligned (frequent exact angles), random valid counts."""
    rng = np.random.default_rng(seed)
    pts = rng.normal(0.0, 0.3, (n, 2, v, 3)).astype(np.float32)
    nrm = rng.normal(size=(n, 2, v, 3))
    axis = rng.random((n, 2, v)) < 0.5
    nrm[axis] = np.eye(3)[rng.integers(0, 3, axis.sum())] * rng.choice([-1, 1], (axis.sum(), 1))
    nrm = (nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)).astype(np.float32)
    cnt = rng.integers(0, v + 1, (n, 2)).astype(np.int32)
    cnt[0] = (v, v)  # every tile
    cnt[1] = (0, 17)  # an empty object
    cnt[2] = (1, v)
    return pts, nrm, cnt


def _args(pts, nrm, cnt):
    return pts[:, 0], nrm[:, 0], cnt[:, 0], pts[:, 1], nrm[:, 1], cnt[:, 1]


def test_rhf_counts_equal_the_fused_loop_batched_and_single():
    pts, nrm, cnt = clouds(0, 9)
    new = jax.jit(jax.vmap(lambda *a: rhf_histograms(*a, RCFG)))(*_args(pts, nrm, cnt))
    old = jax.jit(jax.vmap(lambda *a: rhf_histograms_fused(*a, RCFG)))(*_args(pts, nrm, cnt))
    np.testing.assert_array_equal(np.asarray(new), np.asarray(old))
    assert np.asarray(new)[1].sum() == 0 and abs(float(np.asarray(new)[0].sum()) - 6.0) < 1e-4
    one = jax.jit(lambda *a: rhf_histograms(*a, RCFG))
    for i in (0, 2, 5):
        got = one(*(x[i] for x in _args(pts, nrm, cnt)))
        np.testing.assert_array_equal(np.asarray(got), np.asarray(new)[i])


def test_rhf_counts_nested_vmap_and_unbatched_operands():
    """vmap of vmap, and B's cloud shared (unbatched) by every scene of the batch."""
    pts, nrm, cnt = clouds(1, 6)
    pa, na, ca, pb, nb, cb = _args(pts, nrm, cnt)
    f = jax.jit(jax.vmap(jax.vmap(lambda *a: rhf_histograms(*a, RCFG))))
    got = np.asarray(f(*(x.reshape((2, 3) + x.shape[1:]) for x in (pa, na, ca, pb, nb, cb))))
    want = np.asarray(jax.vmap(lambda *a: rhf_histograms_fused(*a, RCFG))(pa, na, ca, pb, nb, cb))
    np.testing.assert_array_equal(got.reshape(want.shape), want)
    shared = jax.jit(jax.vmap(lambda a, n, c: rhf_histograms(a, n, c, pb[0], nb[0], cb[0], RCFG)))(pa, na, ca)
    ref = jax.vmap(lambda a, n, c: rhf_histograms_fused(a, n, c, pb[0], nb[0], cb[0], RCFG))(pa, na, ca)
    np.testing.assert_array_equal(np.asarray(shared), np.asarray(ref))


def test_rhf_counts_equal_the_fused_loop_at_the_stage_tile():
    """The tile the features stage runs (``culled.RHF_CHUNK`` = 128), clouds past one tile."""
    from relaff_jax.perception.culled import RHF_CHUNK
    rcfg = dataclasses.replace(RCFG, chunk=RHF_CHUNK)
    pts, nrm, cnt = clouds(2, 4, v=2 * RHF_CHUNK)
    cnt[3] = (RHF_CHUNK + 3, 2 * RHF_CHUNK - 1)
    new = jax.jit(jax.vmap(lambda *a: rhf_histograms(*a, rcfg)))(*_args(pts, nrm, cnt))
    old = jax.jit(jax.vmap(lambda *a: rhf_histograms_fused(*a, rcfg)))(*_args(pts, nrm, cnt))
    np.testing.assert_array_equal(np.asarray(new), np.asarray(old))


def test_rhf_counts_in_joint_histograms_of_two_features_past_2_17_cells():
    """At 50 bins (the other tests) the loop counts two joint histograms of three features; at
    60 (216,000 cells each) three of two features: the same histograms as the fused loop."""
    from relaff_jax.perception.descriptors import rhf_groups
    assert len(rhf_groups(50)[0]) == 3 and len(rhf_groups(60)[0]) == 2
    rcfg = dataclasses.replace(RCFG, bins=60)
    pts, nrm, cnt = clouds(3, 4)
    new = jax.jit(jax.vmap(lambda *a: rhf_histograms(*a, rcfg)))(*_args(pts, nrm, cnt))
    old = jax.vmap(lambda *a: rhf_histograms_fused(*a, rcfg))(*_args(pts, nrm, cnt))
    np.testing.assert_array_equal(np.asarray(new), np.asarray(old))
