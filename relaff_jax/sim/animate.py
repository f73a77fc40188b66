"""A sample's motor program as an animation: why its label is what it is.

Takes one settled scene (pair, object state) and an action; plans the program with the JAX
planner (``planning.make_plan_fn``), replays it in MuJoCo C (``native.replay_native``,
recording every geom's pose), and draws each recorded frame as a side view (x-z) and a top
view (x-y) of every geom's box outline: the projected corners of the geom's local bounding
box (``MjModel.geom_aabb``), filled with the geom's colour. No OpenGL is needed. Writes a GIF.

``geom_outlines`` is the projection (tested on hand-worked boxes); ``rollout_frames`` the
replay; ``write_gif`` the drawing.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

VIEWS = {"side (x-z)": (0, 2, 1), "top (x-y)": (0, 1, 2)}  # (horizontal, vertical, depth) axes
STEP_SECONDS = 0.004  # PhysicsConfig's default timestep: frames are shown at real time


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise) of 2-D points (N, 2), Andrew's monotone chain."""
    pts = sorted(set(map(tuple, np.round(points, 9))))
    if len(pts) <= 2:
        return np.asarray(pts)

    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2 and np.cross(np.subtract(out[-1], out[-2]), np.subtract(p, out[-2])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.asarray(lower[:-1] + upper[:-1])


def geom_outlines(aabb: np.ndarray, xpos: np.ndarray, xmat: np.ndarray, view: tuple[int, int, int]
                  ) -> list[tuple[np.ndarray, float]]:
    """Outline polygon and depth of every geom in one view.

    aabb: (G, 6) local bounding boxes (centre, half sizes: ``MjModel.geom_aabb``);
    xpos: (G, 3), xmat: (G, 9) or (G, 3, 3) world poses; view: (h, v, depth) axis indices.
    Returns per geom ``(polygon (K, 2), depth)``: the convex hull of the box's 8 corners
    projected on axes h, v, and the centre's coordinate along the depth axis.
    """
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    rot = np.asarray(xmat, float).reshape(-1, 3, 3)
    out = []
    for g in range(len(aabb)):
        local = aabb[g, :3] + signs * aabb[g, 3:]  # (8, 3)
        world = xpos[g] + local @ rot[g].T
        out.append((_hull(world[:, [view[0], view[1]]]), float(xpos[g, view[2]])))
    return out


def _say(progress, phase: str, done: int, total: int) -> None:
    if progress is not None:
        progress(phase, done, total)


def rollout_frames(action: str, pair: int, qpos: np.ndarray, cfg: Any = None, every: int = 10,
                   progress: Callable[[str, int, int], None] | None = None) -> dict[str, Any]:
    """Plan and replay one scene's program in MuJoCo C, recording every ``every`` steps.

    ``progress(phase, done, total)``, if given, hears each phase begin and end ("planning":
    the IK's compile dominates, minutes on two cores; "replaying in MuJoCo C").

    qpos: (14,) settled object state (arm-less layout). Returns ``frames_xpos`` (F, G, 3),
    ``frames_xmat`` (F, G, 9), ``model`` (the pair's MjModel of the arm world), ``label``
    (C replay), ``feasible``, ``every``.
    """
    import jax
    import jax.numpy as jnp

    from relaff_jax.constants import action_id
    from relaff_jax.sim.native import replay_native
    from relaff_jax.sim.planning import make_plan_fn, setup
    from relaff_jax.sim.templates import ActionConfig

    cfg = cfg if cfg is not None else ActionConfig()
    q = np.asarray(qpos, np.float32)[None]
    p = np.asarray([pair], np.int32)
    _say(progress, "planning (compiles the IK first)", 0, 1)
    plan = jax.jit(make_plan_fn(cfg))(action_id(action), jnp.asarray(p), jnp.asarray(q))
    _say(progress, "planning (compiles the IK first)", 1, 1)
    result = {"q_way": np.asarray(plan.q_way), "grip_way": np.asarray(plan.grip_way),
              "feasible": np.asarray(plan.feasible)}
    qvel = np.zeros((1, 12), np.float32)  # the objects' velocities: settled scenes start at rest
    _say(progress, "replaying in MuJoCo C", 0, 1)
    rep = replay_native(action, cfg, p, q, qvel, result, record_every=every)
    _say(progress, "replaying in MuJoCo C", 1, 1)
    return {"frames_xpos": rep["frames_xpos"][0], "frames_xmat": rep["frames_xmat"][0],
            "model": setup(cfg).world.mj_models[int(pair)], "label": bool(rep["label"][0]),
            "feasible": bool(result["feasible"][0]), "every": every}


def _visible(model) -> np.ndarray:
    """Geoms worth drawing: not planes, not the collapsed placeholders of unused parts, not
    fully transparent."""
    size = np.asarray(model.geom_aabb)[:, 3:]
    return (np.asarray(model.geom_type) != 0) & (size.max(1) > 0.0015) & (np.asarray(model.geom_rgba)[:, 3] > 0)


def write_gif(frames: dict[str, Any], out: str | Path, title: str = "", fps: float | None = None,
              progress: Callable[[str, int, int], None] | None = None) -> Path:
    """Draw ``rollout_frames`` output as a GIF (side and top views), written atomically;
    ``progress("drawing frames", f, F)`` after each frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon
    from PIL import Image

    from relaff_jax.io import atomic_write_bytes

    model = frames["model"]
    keep = np.flatnonzero(_visible(model))
    aabb = np.asarray(model.geom_aabb)[keep]
    rgba = np.clip(np.asarray(model.geom_rgba)[keep], 0, 1)
    xs, rs = frames["frames_xpos"][:, keep], frames["frames_xmat"][:, keep]
    lo = xs.reshape(-1, 3).min(0) - 0.1
    hi = xs.reshape(-1, 3).max(0) + 0.1
    images: list = []
    _say(progress, "drawing frames", 0, len(xs))
    for f in range(len(xs)):
        fig = Figure(figsize=(9, 4.2), dpi=80)
        FigureCanvasAgg(fig)
        for k, (name, view) in enumerate(VIEWS.items()):
            ax = fig.add_subplot(1, 2, k + 1)
            outlines = geom_outlines(aabb, xs[f], rs[f], view)
            # far geoms first; the side view looks along +y, the top view down from +z
            order = np.argsort([d if view[2] == 2 else -d for _, d in outlines])
            for g in order:
                poly, _ = outlines[g]
                if len(poly) >= 3:
                    ax.add_patch(Polygon(poly, closed=True, facecolor=rgba[g], edgecolor="k", linewidth=0.3))
            if view[1] == 2:
                ax.axhline(0.0, color="0.5", linewidth=1)  # the table
            ax.set_xlim(lo[view[0]], hi[view[0]])
            ax.set_ylim(min(lo[view[1]], 0.0 if view[1] == 2 else lo[view[1]]), hi[view[1]])
            ax.set_aspect("equal")
            ax.set_title(name, fontsize=9)
            ax.tick_params(labelsize=7)
        t = f * frames["every"] * STEP_SECONDS
        fig.suptitle(f"{title}   t = {t:.2f} s", fontsize=9)
        fig.canvas.draw()
        images.append(Image.fromarray(np.asarray(fig.canvas.buffer_rgba())[..., :3]))
        _say(progress, "drawing frames", f + 1, len(xs))
    fps = fps or 1.0 / (frames["every"] * STEP_SECONDS)
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    atomic_write_bytes(out, buf.getvalue())
    return Path(out)


def animate_sample(action: str, pair: int, qpos: np.ndarray, out: str | Path, title: str = "",
                   cfg: Any = None, every: int = 10,
                   progress: Callable[[str, int, int], None] | None = None) -> dict[str, Any]:
    """``rollout_frames`` then ``write_gif``; returns the frames dict (label, feasible, ...);
    ``progress(phase, done, total)`` hears every phase (see both)."""
    frames = rollout_frames(action, pair, qpos, cfg, every, progress)
    write_gif(frames, out, title=title, progress=progress)
    return frames


__all__: Sequence[str] = ("geom_outlines", "rollout_frames", "write_gif", "animate_sample")
