"""RANSAC plane fit and k-means in JAX: pure functions, explicit PRNG keys, static shapes.

``ransac_plane(points (N, 3), mask (N,), key, threshold, iterations, batch)`` -> plane (4,)
(unit normal n, offset d: n . p + d = 0, least-squares refit on the best hypothesis' inliers),
inliers (N,) bool. ``kmeans_pp_init(points (M, 3), mask (M,), key, k)`` -> (k, 3) k-means++
seeds; ``kmeans_from(points, mask, init (k, 3), iterations)`` -> Lloyd's algorithm from given
seeds (labels (M,) int32, -1 where masked; centroids (k, 3); inertia (); steps ());
``kmeans(points, mask, key, k, iterations, n_init)`` -> the lowest-inertia run of ``n_init``
seedings. Masked points (padding) never count. The caller owns ``jit`` (k, iterations,
n_init, batch are static).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp


def _plane_from(p0, p1, p2):
    """Plane (4,) through three points, or all zeros when they are (nearly) collinear."""
    n = jnp.cross(p1 - p0, p2 - p0)
    ln = jnp.linalg.norm(n)
    ok = ln > 1e-9
    n = jnp.where(ok, n / jnp.where(ok, ln, 1.0), 0.0)
    return jnp.concatenate([n, -(n @ p0)[None]])


def refit_plane(points, w):
    """Least-squares plane (4,) of the points with weight ``w`` (N,) in {0, 1}: through their
    centroid, normal = the covariance's smallest-eigenvalue eigenvector."""
    n = jnp.maximum(jnp.sum(w), 1.0)
    mu = jnp.sum(points * w[:, None], axis=0) / n
    d = (points - mu) * w[:, None]
    _, vecs = jnp.linalg.eigh(d.T @ d / n)
    normal = vecs[:, 0]
    return jnp.concatenate([normal, -(normal @ mu)[None]])


def ransac_plane(points, mask, key, threshold: float, iterations: int, batch: int):
    """Largest plane by RANSAC (see the module docstring). Hypotheses draw three valid points
    uniformly (with replacement; a degenerate triple scores 0); the score is the inlier count
    (distance < ``threshold``). Returns (plane (4,), inliers (N,) bool, n_inliers ())."""
    n_pts = points.shape[0]
    idx = jnp.nonzero(mask, size=n_pts, fill_value=0)[0]
    nv = jnp.maximum(jnp.sum(mask), 1)
    chunks = -(-iterations // batch)

    def score(plane):
        dist = jnp.abs(points @ plane[:3] + plane[3])
        return jnp.sum((dist < threshold) & mask & jnp.any(plane[:3] != 0))

    def step(best, k):
        pick = idx[jax.random.randint(k, (batch, 3), 0, nv)]
        planes = jax.vmap(_plane_from)(points[pick[:, 0]], points[pick[:, 1]], points[pick[:, 2]])
        scores = jax.vmap(score)(planes)
        i = jnp.argmax(scores)
        better = scores[i] > best[1]
        return (jnp.where(better, planes[i], best[0]), jnp.where(better, scores[i], best[1])), None

    init = (jnp.zeros(4, points.dtype), jnp.int32(-1))
    (plane, _), _ = jax.lax.scan(step, init, jax.random.split(key, chunks))
    inl = (jnp.abs(points @ plane[:3] + plane[3]) < threshold) & mask
    plane = refit_plane(points, inl.astype(points.dtype))
    inl = (jnp.abs(points @ plane[:3] + plane[3]) < threshold) & mask
    return plane, inl, jnp.sum(inl)


def _sq_dist(points, centroids):
    """(M, k) squared distances."""
    return jnp.sum((points[:, None, :] - centroids[None, :, :]) ** 2, axis=-1)


def kmeans_pp_init(points, mask, key, k: int):
    """k-means++ seeds (k, 3): the first a uniform valid point, each next one a valid point
    drawn with probability proportional to its squared distance to the nearest seed so far."""
    w = mask.astype(points.dtype)
    keys = jax.random.split(key, k)
    first = points[jax.random.choice(keys[0], points.shape[0], p=w / jnp.maximum(w.sum(), 1.0))]
    cents = jnp.zeros((k, 3), points.dtype).at[0].set(first)

    def body(j, cents):
        d2 = jnp.min(jnp.where(jnp.arange(k)[None, :] < j, _sq_dist(points, cents), jnp.inf), axis=1)
        p = jnp.where(mask, d2, 0.0)
        tot = jnp.sum(p)
        p = jnp.where(tot > 0, p / jnp.where(tot > 0, tot, 1.0), w / jnp.maximum(w.sum(), 1.0))
        return cents.at[j].set(points[jax.random.choice(keys[j], points.shape[0], p=p)])

    return jax.lax.fori_loop(1, k, body, cents)


def kmeans_from(points, mask, init, iterations: int):
    """Lloyd's algorithm from ``init`` (k, 3): assign each valid point to its nearest centroid,
    move each centroid to its points' mean (an empty cluster keeps its centroid), until no
    assignment changes or ``iterations`` steps. Returns dict(labels (M,) int32 (-1 masked),
    centroids (k, 3), inertia () sum of squared distances, steps ())."""
    k = init.shape[0]
    w = mask.astype(points.dtype)

    def assign(c):
        return jnp.argmin(_sq_dist(points, c), axis=1).astype(jnp.int32)

    def update(lab):
        oh = jax.nn.one_hot(lab, k, dtype=points.dtype) * w[:, None]
        cnt = oh.sum(0)
        s = oh.T @ points
        return cnt, s

    def cond(st):
        it, _, _, changed = st
        return (it < iterations) & changed

    def body(st):
        it, c, lab, _ = st
        cnt, s = update(lab)
        c = jnp.where(cnt[:, None] > 0, s / jnp.maximum(cnt, 1.0)[:, None], c)
        new = assign(c)
        return it + 1, c, new, jnp.any((new != lab) & mask)

    lab0 = assign(init)
    steps, cents, lab, _ = jax.lax.while_loop(cond, body, (jnp.int32(0), init, lab0, jnp.bool_(True)))
    inertia = jnp.sum(jnp.where(mask, jnp.min(_sq_dist(points, cents), axis=1), 0.0))
    return dict(labels=jnp.where(mask, lab, -1), centroids=cents, inertia=inertia, steps=steps)


def kmeans(points, mask, key, k: int, iterations: int, n_init: int):
    """Best of ``n_init`` k-means++-seeded runs of ``kmeans_from`` (lowest inertia); same dict."""
    runs = jax.vmap(lambda kk: kmeans_from(points, mask, kmeans_pp_init(points, mask, kk, k), iterations))(
        jax.random.split(key, n_init))
    best = jnp.argmin(runs["inertia"])
    return jax.tree.map(lambda x: x[best], runs)
