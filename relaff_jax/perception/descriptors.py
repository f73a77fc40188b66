"""Stages 4-5: the paper's two state spaces from voxel clouds.

PCA: ``pca_object(points (V, 3), mask (V,), min_points) -> ((9,), unseen)`` (centroid,
roll/pitch/yaw of the eigenvector frame, eigenvalues). RHF: ``rhf_histograms`` of two clouds
with normals -> (6 * bins,) relational histograms over all point pairs.
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.config.perception import RHF_NAMES, RHFConfig
from .ops import scatter_add


def _sign_fix(v, order):
    """Flip ``v`` so its first component (in ``order``) with |c| > 1e-6 is positive."""
    comps = v[jnp.asarray(order)]
    big = jnp.abs(comps) > 1e-6
    first = jnp.argmax(big)
    s = jnp.where(jnp.any(big), jnp.sign(comps[first]), 1.0)
    return v * jnp.where(s == 0, 1.0, s)


def rotation_to_rpy(rot):
    """(roll, pitch, yaw) with rot = Rz(yaw) @ Ry(pitch) @ Rx(roll); pitch in [-pi/2, pi/2]."""
    yaw = jnp.arctan2(rot[1, 0], rot[0, 0])
    pitch = jnp.arctan2(-rot[2, 0], jnp.hypot(rot[0, 0], rot[1, 0]))
    roll = jnp.arctan2(rot[2, 1], rot[2, 2])
    return jnp.stack([roll, pitch, yaw])


def pca_frame(points, mask):
    """Centroid (3,), right-handed eigenvector frame (3, 3) and eigenvalues (3,) descending.

    points: (V, 3), mask: (V,). Covariance is the population one (divide by n). Frame columns:
    x = major axis with its first non-zero component among (x, y, z) positive, z = minor axis
    with its first non-zero component among (z, x, y) positive, y = z cross x.
    """
    w = mask.astype(points.dtype)
    n = jnp.maximum(jnp.sum(w), 1.0)
    mu = jnp.sum(points * w[:, None], axis=0) / n
    d = (points - mu) * w[:, None]
    cov = d.T @ d / n
    evals, evecs = jnp.linalg.eigh(cov)  # ascending
    x = _sign_fix(evecs[:, 2], (0, 1, 2))
    z = _sign_fix(evecs[:, 0], (2, 0, 1))
    y = jnp.cross(z, x)
    return mu, jnp.stack([x, y, z], axis=1), evals[::-1]


def pca_object(points, mask, min_points: int):
    """Nine PCA values of one object and its ``unseen`` flag.

    Returns (9,) [x, y, z, roll, pitch, yaw, eig_major, eig_middle, eig_minor] and a bool that
    is True when fewer than ``min_points`` voxels were seen; then all nine values are 0.
    """
    n = jnp.sum(mask)
    unseen = n < min_points
    # A well-posed dummy cloud for the unseen branch keeps eigh free of NaN.
    mu, frame, evals = pca_frame(points, mask)
    feats = jnp.concatenate([mu, rotation_to_rpy(frame), evals])
    feats = jnp.where(unseen | ~jnp.all(jnp.isfinite(feats)), 0.0, feats)
    return feats, unseen


# ----------------------------------------------------------------------------- 5. RHF

# Abramowitz & Stegun 4.4.46: acos(x) = sqrt(1 - x) * poly(x) on [0, 1], |error| <= 2e-8.
# XLA's CPU acos/atan2 cost ~25-55 ns per value; this costs ~1 ns.
_ACOS_COEF = (1.5707963050, -0.2145988016, 0.0889789874, -0.0501743046,
              0.0308918810, -0.0170881256, 0.0066700901, -0.0012624911)


def fast_arccos(x):
    """arccos of x clipped to [-1, 1], accurate to ~4e-7 rad in float32."""
    x = jnp.clip(x, -1.0, 1.0)
    ax = jnp.abs(x)
    p = jnp.full_like(ax, _ACOS_COEF[-1])
    for c in _ACOS_COEF[-2::-1]:
        p = p * ax + c
    r = jnp.sqrt(jnp.maximum(1.0 - ax, 0.0)) * p
    return jnp.where(x < 0, jnp.float32(np.pi) - r, r)


def rhf_pair_values(a, na, b, nb):
    """The six RHF values of pairs, as a list of six arrays. a, na, b, nb: lists of the three
    coordinate arrays (any broadcastable shapes) of A's point and unit normal, B's point and
    unit normal.

    dx, dy, dz of d = b - a; |d|; angle(n_a, n_b) = acos(n_a . n_b);
    angle(n_a, d) = acos(n_a . d / |d|), defined as 0 when d = 0.
    """
    d = [b[i] - a[i] for i in range(3)]
    dist = jnp.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    cos_nn = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]
    dot_nd = na[0] * d[0] + na[1] * d[1] + na[2] * d[2]
    cos_nd = jnp.where(dist > 0, dot_nd / jnp.where(dist > 0, dist, 1.0), 1.0)
    return [d[0], d[1], d[2], dist, fast_arccos(cos_nn), fast_arccos(cos_nd)]


def rhf_bin(value, feature: int, rcfg: RHFConfig):
    """Bin of values of feature ``feature``: floor((v - lo) / (hi - lo) * bins) clipped to
    [0, bins - 1] (out-of-range values go to the end bins)."""
    lo, hi = rcfg.ranges[feature]
    b = jnp.floor((value - np.float32(lo)) * np.float32(rcfg.bins / (hi - lo)))
    return jnp.clip(b, 0, rcfg.bins - 1).astype(jnp.int32)


def _rhf_tiles(pa, na, ca, pb, nb, cb, rcfg: RHFConfig):
    """(ca, cb, tb, load, index): what both RHF loops share. ``load(t)`` gives pair tile t
    (A's and B's points, normals (3, C), validity (C,)); ``index(tiles)`` the three joint-bin
    indices (a list of three (C, C)) of its pairs (invalid pairs: the dump slot 3 * bins^2)
    in the joint histograms of ``_PAIRS``."""
    C, nbin = rcfg.chunk, rcfg.bins
    V = pa.shape[0]
    if V % C:
        raise ValueError(f"point capacity {V} is not a multiple of rhf.chunk {C}")
    ca = jnp.minimum(ca, V).astype(jnp.int32)
    cb = jnp.minimum(cb, V).astype(jnp.int32)
    tb = jnp.maximum((cb + C - 1) // C, 1)
    ar = jnp.arange(C)
    pa_t, na_t, pb_t, nb_t = pa.T, na.T, pb.T, nb.T  # (3, V) structure of arrays

    def load(t):
        i, j = t // tb, t % tb
        sl = lambda x, k: jax.lax.dynamic_slice(x, (0, k * C), (3, C))
        return sl(pa_t, i), sl(na_t, i), (i * C + ar) < ca, sl(pb_t, j), sl(nb_t, j), (j * C + ar) < cb

    def index(tiles):
        a, an, wa, b, bn, wb = tiles
        w = wa[:, None] & wb[None, :]
        vals = rhf_pair_values(a[:, :, None], an[:, :, None], b[:, None, :], bn[:, None, :])
        return _joint_index([rhf_bin(v, f, rcfg) for f, v in enumerate(vals)], w, _PAIRS, nbin)

    return ca, cb, tb, load, index


_PAIRS = ((0, 1), (2, 3), (4, 5))  # (dx, dy), (dz, |d|), (the two angles)
_JOINT_MAX = 1 << 17  # the most bins of one joint histogram of three features


def rhf_groups(bins: int) -> tuple:
    """The feature groups (indices into ``RHF_NAMES``) whose joint histograms the RHF loop
    counts, one scatter update per group and pair: (dx, dy, dz) and (|d|, both angles) while
    bins^3 <= 2^17 (50 bins: 125,000 each, both 1 MB: ~15 % faster than three joint 50 x 50
    histograms, benchmarks/perception_stages.py), else the three pairs (dx, dy), (dz, |d|),
    (the angles). Integer counts: any grouping gives the same histograms."""
    return ((0, 1, 2), (3, 4, 5)) if bins ** 3 <= _JOINT_MAX else _PAIRS


def _rhf_normalise(hist, ca, cb, nbin, groups):
    """(6 * bins,) histograms from the joint count histograms ``hist`` of ``groups``
    (len(groups) * bins^g + 1,) (the last slot: invalid pairs)."""
    g = len(groups[0])
    joint = hist[:len(groups) * nbin ** g].reshape((len(groups),) + (nbin,) * g)
    marg = {f: joint[q].sum(axis=tuple(a for a in range(g) if a != i))
            for q, grp in enumerate(groups) for i, f in enumerate(grp)}
    marg = jnp.stack([marg[f] for f in range(len(RHF_NAMES))])
    pairs = ca.astype(jnp.float32) * cb.astype(jnp.float32)
    out = marg.astype(jnp.float32) / jnp.maximum(pairs, 1.0)
    return jnp.where(pairs > 0, out, 0.0).reshape(-1)


def _joint_index(bins, w, groups, nbin):
    """The joint-bin index of each pair in each group's histogram (a list, one per group);
    invalid pairs (``w`` False) go to the dump slot len(groups) * nbin^g."""
    size = nbin ** len(groups[0])
    out = []
    for q, grp in enumerate(groups):
        code = bins[grp[0]]
        for f in grp[1:]:
            code = code * nbin + bins[f]
        out.append(jnp.where(w, q * size + code, len(groups) * size))
    return out


# Rows of A per pair tile of ``rhf_histograms`` (its columns: ``rhf.chunk`` points of B).
RHF_ROWS = 16


def _rhf_rows_tiles(pa, na, ca, pb, nb, cb, rcfg: RHFConfig):
    """(n_tiles, load, index) of the pair tiles ``rhf_histograms`` counts: R = ``RHF_ROWS`` rows
    of A by C = ``rhf.chunk`` consecutive points of B, taken from the sequence of (row block,
    j) for j < cb, so a tile that reaches B's end carries on with the next row block's first
    points (when cb >= C; otherwise each row block is one tile of C columns, those past cb
    invalid). Every valid pair lies in exactly one tile, and only the last tile and A's last
    row block are partly padded (on settled scenes ~1.03 slots per pair, against ~1.48 for
    square tiles of 128). ``load(t)`` gives tile t's A rows of its two row blocks (points and
    normals (3, R) each), the column's row block (0 or 1, (C,)), B's points and normals
    (3, C) and the pair validity (R, C); ``index(tiles)`` the joint-bin indices of its pairs,
    one (R, C) array per group of ``rhf_groups`` (invalid pairs: the dump slot)."""
    C, R, nbin = rcfg.chunk, min(RHF_ROWS, rcfg.chunk), rcfg.bins
    V = pa.shape[0]
    ca = jnp.minimum(ca, V).astype(jnp.int32)
    cb = jnp.minimum(cb, V).astype(jnp.int32)
    n_blocks = (ca + R - 1) // R
    row_len = jnp.maximum(cb, C)  # a row block's stretch of the sequence
    n_tiles = (n_blocks * row_len + C - 1) // C
    # A padded by a row block (the next block's slice never clamps); B followed by its own first
    # C points at cb, so a wrapped tile reads B[j0:j0 + C] as one slice.
    a_t = jnp.concatenate([pa.T, na.T], 0)  # (6, V) structure of arrays
    a_t = jnp.concatenate([a_t, jnp.zeros((6, R), a_t.dtype)], 1)
    b_t = jnp.concatenate([pb.T, nb.T], 0)
    b_t = jnp.concatenate([b_t, jnp.zeros((6, C), b_t.dtype)], 1)
    b_t = jax.lax.dynamic_update_slice(b_t, b_t[:, :C], (0, cb))
    rows, cols = jnp.arange(R), jnp.arange(C)
    groups = rhf_groups(nbin)

    def load(t):
        s = t * C
        blk, j0 = s // row_len, s % row_len
        nxt = (j0 + cols >= row_len).astype(jnp.int32)  # column in the next row block
        j = j0 + cols - nxt * row_len
        a0 = jax.lax.dynamic_slice(a_t, (0, blk * R), (6, R))
        a1 = jax.lax.dynamic_slice(a_t, (0, blk * R + R), (6, R))
        b = jax.lax.dynamic_slice(b_t, (0, j0), (6, C))
        w = ((blk + nxt) * R)[None, :] + rows[:, None] < ca
        w = w & (j < cb)[None, :]  # past the sequence's end: a row block >= n_blocks, invalid above
        return a0, a1, nxt, b, w

    def index(tiles):
        a0, a1, nxt, b, w = tiles
        a = jnp.where(nxt[None, None, :] > 0, a1[:, :, None], a0[:, :, None])  # (6, R, C)
        vals = rhf_pair_values(a[:3], a[3:], b[:3, None, :], b[3:, None, :])
        return _joint_index([rhf_bin(v, f, rcfg) for f, v in enumerate(vals)], w, groups, nbin)

    return n_tiles, load, index


@functools.lru_cache(maxsize=None)
def _rhf_counts_for(rcfg: RHFConfig):
    """``counts(pa, na, ca, pb, nb, cb) -> (len(groups) * bins^g + 1,) int32``: the joint count
    histograms of ``rhf_groups`` of one scene (the last slot collects invalid pairs), built
    once per config."""
    groups = rhf_groups(rcfg.bins)

    @jax.custom_batching.custom_vmap
    def counts(pa, na, ca, pb, nb, cb):
        n_tiles, load, index = _rhf_rows_tiles(pa, na, ca, pb, nb, cb, rcfg)

        def body(state):
            # The current tiles travel in the loop state: read as loop parameters, the pair
            # arithmetic vectorises (with the dynamic slices fused into it, it ran ~10x
            # slower). The indices stay (groups, R, C): flattened to 1-D inside the fusion, XLA CPU
            # computes each pair's (i, j) by division and gathers its operands unvectorised
            # (~5x slower per tile).
            t, hist, tiles = state
            idx = jnp.stack(index(tiles))
            return t + 1, scatter_add(hist, idx, jnp.ones_like(idx)), load(t + 1)

        init = (jnp.int32(0), jnp.zeros(len(groups) * rcfg.bins ** len(groups[0]) + 1, jnp.int32),
                load(jnp.int32(0)))
        return jax.lax.while_loop(lambda s: s[0] < n_tiles, body, init)[1]

    @counts.def_vmap
    def _rule(axis_size, in_batched, *args):
        # Scenes one after another, each loop to its own tile count: a vmapped loop runs every
        # scene to the batch's longest (1.7x the pairs on settled scenes, and a padded pair
        # costs as much as a valid one).
        args = [x if b else jnp.broadcast_to(x, (axis_size,) + x.shape) for x, b in zip(args, in_batched)]
        return jax.lax.map(lambda a: counts(*a), tuple(args)), True

    return counts


def rhf_histograms(pa, na, ca, pb, nb, cb, rcfg: RHFConfig):
    """Six histograms over all pairs (a in object A, b in object B), tile by tile.

    pa, na: (V, 3) points and unit normals of A with the first ``ca`` valid; likewise pb, nb, cb.
    Values per pair: ``rhf_pair_values``; bins: ``rhf_bin``. Work is done on tiles of
    ``RHF_ROWS`` points of A by ``chunk`` consecutive points of B (a tile reaching B's end
    carries on with the next rows, ``_rhf_rows_tiles``) in a while loop over only the tiles
    that hold valid pairs, so memory is bounded and time follows ca * cb, not V * V. Counts are
    accumulated in the joint histograms of ``rhf_groups`` ((dx, dy, dz) and (|d|, both angles)
    at 50 bins) -- one scatter per tile for all groups -- and marginalised at the end (exact:
    the same counts). Under ``vmap`` the
    scenes run one after another, each loop to its own tile count (integer counts: the same
    bits as any order). Returns (6 * bins,): counts divided by ca * cb (each histogram sums to
    1), or all zeros if ca * cb == 0.
    """
    ca, cb = jnp.asarray(ca, jnp.int32), jnp.asarray(cb, jnp.int32)
    hist = _rhf_counts_for(rcfg)(jnp.asarray(pa), jnp.asarray(na), ca, jnp.asarray(pb), jnp.asarray(nb), cb)
    return _rhf_normalise(hist, jnp.minimum(ca, pa.shape[0]), jnp.minimum(cb, pb.shape[0]), rcfg.bins,
                          rhf_groups(rcfg.bins))


def rhf_histograms_fused(pa, na, ca, pb, nb, cb, rcfg: RHFConfig):
    """``rhf_histograms`` as it was computed before (same bits): the bin indices flattened and
    fused into three scatters per tile, a vmapped loop run to the batch's longest scene. Kept as
    the reference of ``tests/perception/test_rhf_counts.py`` and ``benchmarks/perception_stages.py``."""
    ca, cb, tb, load, index = _rhf_tiles(pa, na, ca, pb, nb, cb, rcfg)
    n_tiles = (ca + rcfg.chunk - 1) // rcfg.chunk * tb

    def body(state):
        t, hist, tiles = state
        for idx in index(tiles):
            idx = idx.reshape(-1)
            hist = scatter_add(hist, idx, jnp.ones_like(idx))
        return t + 1, hist, load(t + 1)

    init = (jnp.int32(0), jnp.zeros(3 * rcfg.bins ** 2 + 1, jnp.int32), load(jnp.int32(0)))
    hist = jax.lax.while_loop(lambda s: s[0] < n_tiles, body, init)[1]
    return _rhf_normalise(hist, ca, cb, rcfg.bins, _PAIRS)
