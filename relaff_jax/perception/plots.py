"""Pictures of what the robot saw in one scene.

Takes one unbatched ``SceneGeoms``, a PRNG key and a ``PerceptionConfig``; ``scene_view``
gives the numpy arrays a picture needs (noisy depth (H, W), segments (H, W), object pixels,
voxel clouds, PCA frames, features); ``render_scene_png`` draws them into a PNG.

Drawing uses ``matplotlib.figure.Figure`` with the Agg canvas, never pyplot, so importing or
calling this never changes the matplotlib backend of a notebook or script.
"""
from __future__ import annotations

import functools
import io

import jax
import numpy as np

from relaff_jax.constants import OBJECT_SEGMENTS
from relaff_jax.io import atomic_write_bytes

from relaff_jax.config.perception import PerceptionConfig
from .cloud_plot import draw_clouds
from .descriptors import pca_frame
from .noise import add_depth_noise
from .pipeline import features_from_voxels, point_cloud
from .render import render
from .scene import SceneGeoms

OBJECT_NAMES = ("toy", "other")
OBJECT_COLOURS = ("tab:orange", "tab:purple")


@functools.lru_cache(maxsize=8)
def _scene_view_fn(geom_type: tuple, geom_seg: tuple, cfg: PerceptionConfig):
    """Jitted (cached per layout and config) view of one scene for ``scene_view``."""

    def view(size, xpos, xmat, key):
        scene = SceneGeoms(geom_type, geom_seg, size, xpos, xmat)
        k_img, k_feat = jax.random.split(key)
        full = render(scene, cfg)
        if cfg.noise.model != "none":
            full = add_depth_noise(full, k_img, cfg)
        pc = point_cloud(scene, k_feat, cfg)
        frames = [pca_frame(pc["voxels"]["points"][o], pc["voxels"]["mask"][o]) for o in range(2)]
        return dict(depth=full["depth"], seg=full["seg"].reshape(full["depth"].shape),
                    pixels=pc["pixels"], voxels=pc["voxels"], frames=frames,
                    feats=features_from_voxels(pc["voxels"], cfg))

    return jax.jit(view)


def scene_view(scene: SceneGeoms, key, cfg: PerceptionConfig = PerceptionConfig()) -> dict:
    """Everything a picture of one (unbatched) scene needs, as numpy: depth (H, W) (noisy,
    0 = no return), seg (H, W), pixels (noisy ``compact_objects`` result), voxels
    (``voxel_downsample`` result), frames (per object: centroid, frame, eigenvalues) and
    feats (the ``features`` outputs). ``key`` is split: image noise, feature noise."""
    fn = _scene_view_fn(scene.geom_type, scene.geom_seg, cfg)
    return jax.tree.map(np.asarray, fn(scene.size, scene.xpos, scene.xmat, key))


def object_crop(seg, margin: float = 0.25, min_margin: int = 8):
    """Image window (r0, r1, c0, c1) around the object pixels (segments 1, 2) of ``seg``
    (H, W): their bounding box grown by ``margin`` of its larger side (at least
    ``min_margin`` px) and clipped to the image; None if no object pixel is visible."""
    rows, cols = np.nonzero(np.isin(seg, OBJECT_SEGMENTS))
    if rows.size == 0:
        return None
    m = max(min_margin, int(np.ceil(margin * max(np.ptp(rows), np.ptp(cols)))))
    h, w = seg.shape
    return (max(rows.min() - m, 0), min(rows.max() + m + 1, h),
            max(cols.min() - m, 0), min(cols.max() + m + 1, w))


def _draw_depth(fig, ax, depth):
    """Whole noisy depth image; its colour scale spans the table (metres)."""
    im = ax.imshow(np.ma.masked_where(depth <= 0, depth), cmap="viridis")
    fig.colorbar(im, ax=ax, fraction=0.035, label="depth z (m)")
    ax.set_title("depth image (noisy)")


def _draw_depth_crop(fig, ax, depth, seg, crop):
    """The objects' depth pixels in ``crop`` on a colour scale of their own (the table, metres
    deeper, would use up a shared scale); other valid pixels light grey."""
    from matplotlib.colors import ListedColormap
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    r0, r1, c0, c1 = crop
    d, s = depth[r0:r1, c0:c1], seg[r0:r1, c0:c1]
    obj = np.isin(s, OBJECT_SEGMENTS) & (d > 0)
    extent = (c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5)  # axes in full-image pixel coordinates
    ax.imshow(np.ma.masked_where(~(d > 0) | obj, np.ones_like(d)), cmap=ListedColormap(["0.85"]),
              vmin=0, vmax=1, extent=extent, interpolation="nearest")
    im = ax.imshow(np.ma.masked_where(~obj, d), cmap="viridis", vmin=d[obj].min(), vmax=d[obj].max(),
                   extent=extent, interpolation="nearest")
    cax = make_axes_locatable(ax).append_axes("right", size="4%", pad=0.05)  # as tall as the crop
    fig.colorbar(im, cax=cax, label="object depth z (m)")
    ax.set_title(f"objects' depth, own scale (rows {r0}-{r1 - 1}, cols {c0}-{c1 - 1})", fontsize=9)


def _draw_segments(ax, seg, crop):
    """Segment labels in ``crop`` (the whole image if None): black no return, grey table."""
    from matplotlib.colors import ListedColormap

    r0, r1, c0, c1 = crop if crop is not None else (0, seg.shape[0], 0, seg.shape[1])
    cmap = ListedColormap(["black", "0.75", *OBJECT_COLOURS])
    ax.imshow(seg[r0:r1, c0:c1] + 1, cmap=cmap, vmin=0, vmax=3, interpolation="nearest",
              extent=(c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5))
    ax.set_title("segments: table grey, toy orange, other purple", fontsize=9)


def _draw_clouds(ax, v, cfg: PerceptionConfig):
    """Voxel clouds with PCA frames, the robot base marked."""
    feats = v["feats"]
    counts = [int(min(v["voxels"]["count"][o], cfg.voxel.max_voxels)) for o in range(2)]
    points = [v["voxels"]["points"][o][:counts[o]] for o in range(2)]
    frames = [None if feats["unseen"][o] else v["frames"][o] for o in range(2)]
    ax.scatter([0], [0], [0], marker="^", c="k", s=40, label="robot base")
    pca = feats["pca"]
    title = ("voxel clouds, PCA frames (x red, y green, z blue)\n"
             f"toy yaw {np.rad2deg(pca[5]):.0f} deg, other yaw {np.rad2deg(pca[14]):.0f} deg"
             + ("  [UNSEEN: " + ", ".join(n for n, u in zip(OBJECT_NAMES, feats["unseen"]) if u)
                + ": fewer voxels than a frame needs, so its 9 PCA values are zeros]" if feats["unseen"].any() else ""))
    draw_clouds(ax, points, [f"{n}: {c} voxels" for n, c in zip(OBJECT_NAMES, counts)], OBJECT_COLOURS,
                frames, title, min_half=0.3)


def render_scene_png(scene: SceneGeoms, key, out_path, cfg: PerceptionConfig = PerceptionConfig(),
                     title: str | None = None) -> dict:
    """Draw what the robot saw: the noisy depth image (the crop window outlined), a crop around
    the two objects with its own depth colour scale, the segmentation of that crop, and the
    objects' voxel clouds with their PCA frames; writes a PNG atomically. Jits one view
    function per (layout, config), cached. Does not touch the matplotlib backend.

    scene: one unbatched ``SceneGeoms``. Returns the ``scene_view`` dict."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    v = scene_view(scene, key, cfg)
    crop = object_crop(v["seg"])
    fig = Figure(figsize=(20, 4.8))
    FigureCanvasAgg(fig)
    ax0 = fig.add_subplot(1, 4, 1)
    _draw_depth(fig, ax0, v["depth"])
    ax1 = fig.add_subplot(1, 4, 2)
    if crop is None:
        ax1.text(0.5, 0.5, "no object pixels in view", ha="center", va="center", transform=ax1.transAxes)
        ax1.set_title("objects' depth")
    else:
        r0, r1, c0, c1 = crop
        ax0.add_patch(Rectangle((c0 - 0.5, r0 - 0.5), c1 - c0, r1 - r0, fill=False, ec="red", lw=1))
        _draw_depth_crop(fig, ax1, v["depth"], v["seg"], crop)
    ax2 = fig.add_subplot(1, 4, 3)
    _draw_segments(ax2, v["seg"], crop)
    for a in (ax0, ax1, ax2):
        a.set_xticks([])
        a.set_yticks([])
    _draw_clouds(fig.add_subplot(1, 4, 4, projection="3d"), v, cfg)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    atomic_write_bytes(out_path, buf.getvalue())
    return v
