"""``RealCloud``: one real point cloud as the readers give it, and its camera intrinsics.

Takes arrays from a reader; gives a frozen ``RealCloud`` (fields below), ``make_cloud`` (checks
shapes and estimates intrinsics of an organized cloud), ``estimate_intrinsics`` (pinhole fit)
and the colour (un)packing of PCD ``rgb``/``rgba`` fields.

Segment maps, used by every later stage: ``(H, W)`` (or ``(N,)``) int32 with ``SEG_NONE`` = 0
(no point, background or unassigned), ``SEG_TABLE`` = 1, and an object's id >= 2 (for the
hand segmentation the database's own ``label // 10``).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from relaff_jax.errors import UserError

SEG_NONE, SEG_TABLE = 0, 1
FIRST_OBJECT = 2


@dataclasses.dataclass(frozen=True, eq=False)
class RealCloud:
    """One real scene.

    xyz: (H, W, 3) float32 camera-frame metres (x right, y down, z along the optical axis), or
        (N, 3) for an unorganized cloud; invalid points are NaN.
    rgb: (H, W, 3) / (N, 3) uint8 or None. label: (H, W) / (N,) uint32 or None (the PCD
        ``label`` field: 0 invalid, 1-9 table, object id = label // 10 for label >= 20).
    fields: every other field of the file, name -> (H, W[, count]) / (N[, count]) array.
    intrinsics: (fx, fy, cx, cy) in pixels, or None; intrinsics_source: "file", "estimated"
        (``estimate_intrinsics``) or None. viewpoint: the PCD VIEWPOINT (7 numbers) or None.
    path: where it was read from ("" if built in memory).
    """

    xyz: np.ndarray
    rgb: np.ndarray | None = None
    label: np.ndarray | None = None
    fields: dict = dataclasses.field(default_factory=dict)
    intrinsics: tuple | None = None
    intrinsics_source: str | None = None
    viewpoint: tuple | None = None
    path: str = ""

    @property
    def organized(self) -> bool:
        """True for an image-shaped (H, W, 3) cloud."""
        return self.xyz.ndim == 3

    @property
    def valid(self) -> np.ndarray:
        """(H, W) / (N,) bool: all three coordinates finite."""
        return np.all(np.isfinite(self.xyz), axis=-1)

    @property
    def n_valid(self) -> int:
        return int(np.count_nonzero(self.valid))


def make_cloud(xyz, rgb=None, label=None, fields=None, intrinsics=None, viewpoint=None, path="",
               estimate: bool = True) -> RealCloud:
    """A checked ``RealCloud``: xyz (H, W, 3) or (N, 3) (cast to float32), rgb uint8 of the same
    leading shape, label of the same leading shape (cast to uint32). Without ``intrinsics``, an
    organized cloud with enough valid points gets ``estimate_intrinsics`` (``estimate``)."""
    where = f" in {path}" if path else ""
    xyz = np.asarray(xyz, dtype=np.float32)
    if xyz.ndim not in (2, 3) or xyz.shape[-1] != 3:
        raise UserError(f"xyz must be (H, W, 3) or (N, 3), got shape {xyz.shape}{where}")
    lead = xyz.shape[:-1]
    n_inf = int(np.isinf(xyz).sum())
    if n_inf:  # NaN marks a missing point (organized clouds); infinity is damage
        raise UserError(f"xyz holds {n_inf} infinite coordinates{where} (missing points are NaN)")
    if rgb is not None:
        rgb = np.asarray(rgb)
        if rgb.shape != lead + (3,):
            raise UserError(f"rgb shape {rgb.shape} does not match xyz {xyz.shape}{where}")
        if rgb.dtype != np.uint8:
            if np.issubdtype(rgb.dtype, np.floating) and np.nanmax(rgb, initial=0.0) <= 1.0:
                rgb = np.round(np.nan_to_num(rgb) * 255.0)  # colours stored in [0, 1]
            rgb = np.clip(rgb, 0, 255).astype(np.uint8)
    if label is not None:
        label = np.asarray(label)
        if label.shape != lead:
            raise UserError(f"label shape {label.shape} does not match xyz {xyz.shape}{where}")
        label = label.astype(np.uint32)
    source = None
    if intrinsics is not None:
        intrinsics = tuple(float(v) for v in np.asarray(intrinsics, dtype=np.float64).ravel())
        if len(intrinsics) != 4:
            raise UserError(f"intrinsics must be (fx, fy, cx, cy), got {intrinsics}{where}")
        source = "file"
    elif estimate and xyz.ndim == 3:
        fit = estimate_intrinsics(xyz)
        if fit is not None:
            intrinsics, source = fit["intrinsics"], "estimated"
    vp = None if viewpoint is None else tuple(float(v) for v in viewpoint)
    return RealCloud(xyz=xyz, rgb=rgb, label=label, fields=dict(fields or {}), intrinsics=intrinsics,
                     intrinsics_source=source, viewpoint=vp, path=str(path))


def estimate_intrinsics(xyz, min_points: int = 100) -> dict | None:
    """Pinhole intrinsics of an organized cloud by least squares.

    xyz: (H, W, 3) camera-frame points. For every valid pixel (row v, column u),
    u = fx * x / z + cx and v = fy * y / z + cy; both lines are fitted separately.
    Returns dict(intrinsics=(fx, fy, cx, cy), rms_px=(rms_u, rms_v) residuals in pixels,
    n=points used), or None with fewer than ``min_points`` valid points with z > 0.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[-1] != 3:
        raise UserError(f"estimate_intrinsics needs an organized (H, W, 3) cloud, got {xyz.shape}")
    ok = np.all(np.isfinite(xyz), axis=-1) & (xyz[..., 2] > 0)
    if np.count_nonzero(ok) < min_points:
        return None
    v, u = np.nonzero(ok)
    p = xyz[ok]
    out, rms = [], []
    for a, pix in ((p[:, 0] / p[:, 2], u), (p[:, 1] / p[:, 2], v)):
        A = np.stack([a, np.ones_like(a)], axis=1)
        coef, *_ = np.linalg.lstsq(A, pix.astype(np.float64), rcond=None)
        out.append(coef)
        rms.append(float(np.sqrt(np.mean((A @ coef - pix) ** 2))))
    (fx, cx), (fy, cy) = out
    return dict(intrinsics=(float(fx), float(fy), float(cx), float(cy)), rms_px=tuple(rms), n=int(len(p)))


def unpack_rgb(packed) -> np.ndarray:
    """PCD packed colour (uint32 0xAARRGGBB, or its bits stored as float32) -> (..., 3) uint8."""
    packed = np.asarray(packed)
    if packed.dtype.itemsize != 4:
        raise UserError(f"a packed rgb field must be 4 bytes per point, got {packed.dtype}")
    bits = np.ascontiguousarray(packed).view(np.uint32)
    return np.stack([(bits >> 16) & 255, (bits >> 8) & 255, bits & 255], axis=-1).astype(np.uint8)


def pack_rgb(rgb, alpha: int = 255) -> np.ndarray:
    """(..., 3) uint8 -> uint32 0xAARRGGBB (the PCD ``rgba`` convention)."""
    c = np.asarray(rgb).astype(np.uint32)
    return (np.uint32(alpha) << 24) | (c[..., 0] << 16) | (c[..., 1] << 8) | c[..., 2]
