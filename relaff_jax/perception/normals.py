"""Normals from the cloud itself: PCA over an image-space window of an organized depth image.

The same rule serves simulation (``PerceptionConfig.normals.source = "cloud"``, on the noisy
object pixels) and real organized clouds (``config.real.NormalConfig.method = "window"``):

* ``smallest_eigenvector(cov (..., 3, 3)) -> (..., 3)``: unit eigenvector of the smallest
  eigenvalue of symmetric 3x3 matrices, closed form (trigonometric eigenvalues, then the
  largest cross product of two rows of ``cov - lambda_min I``), vectorised;
* ``window_normals(image_points (H*W, 3), image_label (H*W,), pixel (M,), ...) -> (M, 3)``:
  for each query pixel, the covariance of the points in its ``window`` x ``window`` image
  neighbourhood that carry the same label (> 0) and lie within ``radius`` metres of it,
  itself included; normal = its smallest eigenvector, turned towards ``viewpoint``. With
  fewer than 3 such points the normal is the unit vector to the viewpoint;
* ``pixel_normals(pix, cfg) -> (M, 3)``: ``window_normals`` of a ``compact_objects`` result
  (pixel (M,), points (M, 3), seg (M,)), scattered back into the camera image, in the robot frame.
"""
from __future__ import annotations

import jax.numpy as jnp

from relaff_jax.config.perception import PerceptionConfig
from .ops import scatter_set


def smallest_eigenvector(cov):
    """Unit eigenvector (..., 3) of the smallest eigenvalue of symmetric cov (..., 3, 3).

    The matrix is scaled by its largest entry first; an isotropic (or zero) matrix gives (0, 0, 1).
    """
    scale = jnp.max(jnp.abs(cov), axis=(-2, -1), keepdims=True)
    a = cov / jnp.where(scale > 0, scale, 1.0)
    a00, a11, a22 = a[..., 0, 0], a[..., 1, 1], a[..., 2, 2]
    a01, a02, a12 = a[..., 0, 1], a[..., 0, 2], a[..., 1, 2]
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)
    p = jnp.sqrt(p2 / 6.0)
    ps = jnp.where(p > 0, p, 1.0)
    det = (b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02))
    r = jnp.clip(det / (2.0 * ps * ps * ps), -1.0, 1.0)
    phi = jnp.arccos(r) / 3.0
    lam = q + 2.0 * p * jnp.cos(phi + 2.0 * jnp.pi / 3.0)  # smallest eigenvalue
    r0 = jnp.stack([a00 - lam, a01, a02], -1)
    r1 = jnp.stack([a01, a11 - lam, a12], -1)
    r2 = jnp.stack([a02, a12, a22 - lam], -1)
    c = jnp.stack([jnp.cross(r0, r1), jnp.cross(r0, r2), jnp.cross(r1, r2)], -2)  # (..., 3, 3)
    n2 = jnp.sum(c * c, -1)
    best = jnp.argmax(n2, -1)
    v = jnp.take_along_axis(c, best[..., None, None], -2)[..., 0, :]
    vn = jnp.sqrt(jnp.max(n2, -1))[..., None]
    ok = (vn > 0) & (p[..., None] > 0)
    return jnp.where(ok, v / jnp.where(vn > 0, vn, 1.0), jnp.array([0.0, 0.0, 1.0], cov.dtype))


def window_normals(image_points, image_label, pixel, width: int, height: int, window: int,
                   radius: float, viewpoint):
    """Window-PCA normals (M, 3) at flat pixel indices ``pixel`` (M,) (-1: empty, gives 0).

    image_points (H*W, 3) row-major, image_label (H*W,) int (0: no point), viewpoint (3,) in
    the points' frame. See the module docstring for the rule.
    """
    HW = width * height
    ok = (pixel >= 0) & (pixel < HW)
    pc = jnp.where(ok, pixel, 0)
    p = image_points[pc]
    lab = jnp.where(ok, image_label[pc], 0)
    u, v = pc % width, pc // width
    h = window // 2
    n = jnp.zeros(pixel.shape, p.dtype)
    s1 = jnp.zeros(p.shape, p.dtype)
    s2 = jnp.zeros(p.shape[:-1] + (6,), p.dtype)
    r2 = radius * radius
    for dv in range(-h, h + 1):
        for du in range(-h, h + 1):
            inside = (u + du >= 0) & (u + du < width) & (v + dv >= 0) & (v + dv < height)
            j = jnp.where(inside, pc + dv * width + du, 0)
            d = image_points[j] - p
            use = inside & (image_label[j] == lab) & (lab > 0) & (jnp.sum(d * d, -1) <= r2)
            d = jnp.where(use[:, None], d, 0.0)
            n = n + use
            s1 = s1 + d
            s2 = s2 + jnp.stack([d[:, 0] * d[:, 0], d[:, 1] * d[:, 1], d[:, 2] * d[:, 2],
                                 d[:, 0] * d[:, 1], d[:, 0] * d[:, 2], d[:, 1] * d[:, 2]], -1)
    m = s1 / jnp.maximum(n, 1.0)[:, None]
    e = s2 / jnp.maximum(n, 1.0)[:, None] - jnp.stack(
        [m[:, 0] * m[:, 0], m[:, 1] * m[:, 1], m[:, 2] * m[:, 2], m[:, 0] * m[:, 1], m[:, 0] * m[:, 2], m[:, 1] * m[:, 2]], -1)
    cov = jnp.stack([jnp.stack([e[:, 0], e[:, 3], e[:, 4]], -1),
                     jnp.stack([e[:, 3], e[:, 1], e[:, 5]], -1),
                     jnp.stack([e[:, 4], e[:, 5], e[:, 2]], -1)], -2)
    nrm = smallest_eigenvector(cov)
    view = jnp.asarray(viewpoint, p.dtype) - p
    view = view / jnp.maximum(jnp.linalg.norm(view, axis=-1, keepdims=True), 1e-12)
    nrm = jnp.where((n >= 3)[:, None], nrm, view)
    nrm = jnp.where((jnp.sum(nrm * view, -1) < 0)[:, None], -nrm, nrm)
    return jnp.where(ok[:, None], nrm, 0.0)


def pixel_normals(pix: dict, cfg: PerceptionConfig):
    """Cloud normals (M, 3) of a ``compact_objects`` result (noisy or not), robot frame.

    The object pixels are scattered back into an (H*W,) image (the table and background are
    absent, so only same-object neighbours exist) and ``window_normals`` runs with the
    camera's position as the viewpoint and ``cfg.normals`` window and radius.
    """
    cam, nc = cfg.camera, cfg.normals
    HW = cam.width * cam.height
    dest = jnp.where(pix["pixel"] >= 0, pix["pixel"], HW)  # -1 would wrap: send it out of range
    img_p = scatter_set(jnp.zeros((HW, 3), pix["points"].dtype), dest, pix["points"])
    img_l = scatter_set(jnp.zeros((HW,), jnp.int32), dest, pix["seg"].astype(jnp.int32))
    return window_normals(img_p, img_l, pix["pixel"], cam.width, cam.height, nc.window, nc.radius, cam.position)
