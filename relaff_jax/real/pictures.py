"""One picture per object pair of a real scene, to check the proposed relation by eye.

Takes a ``scene_source.RealScene`` and a ``propose.Proposal``; ``pair_picture`` writes a PNG
(atomically) with three panels: the colour image with object a tinted red and object b blue,
the side view (x, z in the table frame) and the top view (x, y), titled with the scene, the
ids and the proposal with its numbers (bottoms, tops, overlaps). ``scene_pictures`` writes
one per pair into a folder and returns the paths. The pictures are for checking labels and
are not shipped; this generator is.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from relaff_jax.io import atomic_write_bytes

from .propose import Proposal
from .scene_source import RealScene


def _tinted(scene: RealScene, a: int, b: int) -> np.ndarray:
    img = scene.rgb.astype(float) / 255.0
    ids = scene.seg
    for oid, colour in ((a, (1.0, 0.1, 0.1)), (b, (0.1, 0.3, 1.0))):
        m = ids == oid
        img[m] = 0.35 * img[m] + 0.65 * np.asarray(colour)
    return img


def pair_picture(scene: RealScene, prop: Proposal, out: str | Path, max_points: int = 4000) -> Path:
    """Write the picture of one pair to ``out`` (PNG); returns the path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    a, b = prop.object_a, prop.object_b
    fig = Figure(figsize=(15, 4.6))
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 3)
    ax[0].imshow(_tinted(scene, a, b))
    ax[0].set_axis_off()
    ax[0].set_title("red = a, blue = b")
    rng = np.random.default_rng(0)
    others = [k for k in scene.objects if k not in (a, b)]
    for oid, colour in [(k, "0.7") for k in others] + [(a, "tab:red"), (b, "tab:blue")]:
        p = scene.objects[oid]
        p = p[rng.choice(len(p), min(len(p), max_points), replace=False)]
        ax[1].scatter(p[:, 0], p[:, 2], s=1, c=colour)
        ax[2].scatter(p[:, 0], p[:, 1], s=1, c=colour)
    ax[1].axhline(0.0, color="k", lw=0.8)
    ax[1].set_xlabel("x (m)")
    ax[1].set_ylabel("z above table (m)")
    ax[1].set_title("side view")
    ax[1].set_aspect("equal")
    ax[2].set_xlabel("x (m)")
    ax[2].set_ylabel("y (m)")
    ax[2].set_title("top view")
    ax[2].set_aspect("equal")
    fig.suptitle(f"{scene.name}: a={a}, b={b}: proposed {prop.relation}   bottoms "
                 f"{prop.bottoms[0]:.3f}/{prop.bottoms[1]:.3f} m, tops {prop.tops[0]:.3f}/{prop.tops[1]:.3f} m, "
                 f"a over b {prop.overlap[0]:.2f}, b over a {prop.overlap[1]:.2f}")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=70)
    atomic_write_bytes(out, buf.getvalue())
    return Path(out)


def scene_pictures(scene: RealScene, proposals: list[Proposal], folder: str | Path) -> list[Path]:
    """One picture per proposal, named ``<scene>_<a>_<b>.png``, in ``folder`` (created)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = Path(scene.name).stem
    return [pair_picture(scene, p, folder / f"{stem}_{p.object_a}_{p.object_b}.png") for p in proposals]
