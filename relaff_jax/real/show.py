"""A picture of one real scene: colour, segmentations, voxel clouds with PCA frames.

Takes a ``RealCloud`` (organized, for the images), a PRNG key and a ``RealConfig``;
``real_scene_view`` gives the numpy arrays a picture needs (pipeline segmentation, hand
segmentation when the cloud has labels, table frame, the chosen pair's ``pair_features`` and
PCA frames); ``render_real_scene_png`` draws them into a PNG (matplotlib ``Figure`` with the
Agg canvas, never pyplot) and writes it atomically.
"""
from __future__ import annotations

import io

import numpy as np

from relaff_jax.errors import UserError
from relaff_jax.io import atomic_write_bytes
from relaff_jax.perception.cloud_plot import draw_clouds
from relaff_jax.perception.descriptors import pca_frame

from .cloud_features import object_pair_features
from relaff_jax.config.real import RealConfig
from .frame import table_frame
from .segment import hand_segmentation, object_ids, segment_scene

def real_scene_view(cloud, key, cfg: RealConfig = RealConfig(), pair=None, source: str = "hand",
                    n_objects: int | None = None) -> dict:
    """Everything the picture needs, as numpy: pipeline (``segment_scene`` result), hand
    (segment map or None), frame (``table_frame`` of the fitted plane), source ("hand" or
    "pipeline": which segmentation gives the pair's points; "hand" needs labels), pair
    (id_a, id_b) (default: the first two objects of that segmentation), feats
    (``pair_features`` result) and frames (per object: centroid, PCA frame, eigenvalues)."""
    if source not in ("hand", "pipeline"):
        raise UserError(f"source must be 'hand' or 'pipeline', got {source!r}")
    hand = hand_segmentation(cloud.label) if cloud.label is not None else None
    if source == "hand" and hand is None:
        raise UserError(f"{cloud.path or 'the cloud'} has no labels; use source='pipeline'")
    if n_objects is None and hand is not None:
        n_objects = len(object_ids(hand)) or None
    pipe = segment_scene(cloud, key, cfg, n_objects=n_objects)
    frame = table_frame(pipe["plane"])
    seg = hand if source == "hand" else pipe["seg"]
    ids = object_ids(seg)
    if pair is None:
        if len(ids) < 2:
            raise UserError(f"{cloud.path or 'the scene'} has {len(ids)} object(s) in the {source} "
                            "segmentation; a pair needs 2")
        pair = (ids[0], ids[1])
    feats = object_pair_features(cloud, seg, pair[0], pair[1], frame, cfg)
    vox = feats["voxels"]
    V = cfg.perception.voxel.max_voxels
    frames = [tuple(np.asarray(x) for x in pca_frame(vox["points"][o], vox["mask"][o])) for o in range(2)]
    counts = [int(min(vox["count"][o], V)) for o in range(2)]
    return dict(pipeline=pipe, hand=hand, frame=frame, source=source, pair=tuple(pair), feats=feats,
                frames=frames, counts=counts)


def _seg_image(ax, seg, valid, title):
    """Segment map: black no point, grey table, one colour per object id."""
    from matplotlib.colors import ListedColormap

    ids = object_ids(seg)
    img = np.where(valid, 1, 0)  # 1 = valid, unassigned
    img = np.where(seg == 1, 2, img)
    for i, o in enumerate(ids):
        img = np.where(seg == o, 3 + i, img)
    cols = ["black", "0.9", "0.6"] + [f"C{i % 10}" for i in range(len(ids))]
    ax.imshow(img, cmap=ListedColormap(cols), vmin=0, vmax=len(cols) - 1, interpolation="nearest")
    ax.set_title(title + (f"; objects {ids}" if ids else "; no objects"), fontsize=9)


def _draw_clouds(ax, v):
    """The pair's voxel clouds in the table frame, each in its colour of the segmentation panel."""
    feats = v["feats"]
    seg = v["hand"] if v["source"] == "hand" else v["pipeline"]["seg"]
    ids = object_ids(seg)
    colours = [f"C{ids.index(o) % 10}" if o in ids else "0.3" for o in v["pair"]]
    points = [feats["voxels"]["points"][o][: v["counts"][o]] for o in range(2)]
    frames = [None if feats["unseen"][o] else v["frames"][o] for o in range(2)]
    draw_clouds(ax, points, [f"object {v['pair'][o]}: {v['counts'][o]} voxels" for o in range(2)], colours, frames,
                f"{v['source']} pair in the table frame (voxel centroids)\nPCA frames (x red, y green, z blue)",
                min_half=0.15, axis_labels=("x (m, viewing dir.)", "y (m)", "z (m, up)"))


def render_real_scene_png(cloud, key, out_path, cfg: RealConfig = RealConfig(), pair=None, source: str = "hand",
                          n_objects: int | None = None, title: str | None = None) -> dict:
    """Draw a real scene: colour image, pipeline segmentation, hand segmentation (if labelled),
    and the pair's voxel clouds with PCA frames; writes a PNG. Returns ``real_scene_view``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not cloud.organized:
        raise UserError(f"{cloud.path or 'the cloud'} is not organized (H, W): no image to draw")
    v = real_scene_view(cloud, key, cfg, pair, source, n_objects)
    valid = cloud.valid
    fig = Figure(figsize=(20, 4.8))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 4, 1)
    if cloud.rgb is not None:
        ax.imshow(np.where(valid[..., None], cloud.rgb, (cloud.rgb * 0.4).astype(np.uint8)))
        ax.set_title("colour (pixels without depth darkened)", fontsize=9)
    else:
        ax.imshow(np.where(valid, cloud.xyz[..., 2], np.nan), cmap="viridis")
        ax.set_title("depth z (m)", fontsize=9)
    _seg_image(fig.add_subplot(1, 4, 2), v["pipeline"]["seg"], valid,
               f"pipeline: RANSAC table + k-means, k = {v['pipeline']['k']}")
    ax3 = fig.add_subplot(1, 4, 3)
    if v["hand"] is not None:
        _seg_image(ax3, v["hand"], valid, "hand segmentation")
    else:
        ax3.text(0.5, 0.5, "no labels in the file", ha="center", va="center", transform=ax3.transAxes)
    for a in fig.axes:
        a.set_xticks([])
        a.set_yticks([])
    _draw_clouds(fig.add_subplot(1, 4, 4, projection="3d"), v)
    fig.suptitle(title or (cloud.path or "real scene"))
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    atomic_write_bytes(out_path, buf.getvalue())
    return v
