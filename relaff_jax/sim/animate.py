"""A sample's motor program as an animation: why its label is what it is.

Takes one settled scene (pair, object state) and an action; plans the program with the JAX
planner generation uses (``rollouts.jitted_stage_fns``, in a call of a dataset's planner rows),
replays it in MuJoCo C (``native.reference.replay_native``, recording every geom's pose), and
draws each recorded frame with the project's ray caster
(``perception.rollout_view``: every primitive as it is, spheres round, shaded, coloured by
geom, from a camera framed on the two objects) under a title that names the engines and
marks an infeasible program. No OpenGL is needed. Writes a GIF.

``rollout_frames`` is the replay; ``write_gif`` the drawing.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from relaff_jax.sim.actions.registry import action_id
from relaff_jax.sim.native.reference import replay_native
from relaff_jax.sim.planning import setup
from relaff_jax.sim.templates import ActionConfig
from relaff_jax.io import atomic_write_bytes
from relaff_jax.perception import rollout_view as rv

STEP_SECONDS = 0.004  # PhysicsConfig's default timestep: frames are shown at real time


def _say(progress, phase: str, done: int, total: int) -> None:
    if progress is not None:
        progress(phase, done, total)


def rollout_frames(action: str, pair: int, qpos: np.ndarray, cfg: Any = None, every: int = 10,
                   progress: Callable[[str, int, int], None] | None = None,
                   qvel: np.ndarray | None = None, batch: int = 8) -> dict[str, Any]:
    """Plan and replay one scene's program in MuJoCo C, recording every ``every`` steps.

    The plan is generation's jitted planner called on ``batch`` copies of the scene (the rows
    of a dataset's planner calls, ``min(rollout_batch, reach_screen.PLAN_CHUNK)``: the program
    its rollouts were planned by, which the compilation cache keeps; default 8, the tiny
    preset's); a plan does not depend on the other rows of its call.

    ``progress(phase, done, total)``, if given, hears each phase begin and end ("planning":
    the IK's compile dominates, minutes on two cores; "replaying in MuJoCo C").

    qpos: (14,) settled object state (arm-less layout); qvel: (12,) its velocities (default at
    rest; a native dataset's re-settled ones reproduce its label exactly, ``data.audit``).
    Returns ``frames_xpos`` (F, G, 3), ``frames_xmat`` (F, G, 9), ``model`` (the pair's MjModel
    of the arm world), ``object_bodies`` (toy, other), ``label`` (C replay), ``feasible``,
    ``every``.
    """
    import jax
    import jax.numpy as jnp

    from relaff_jax.sim.rollouts import jitted_stage_fns

    if int(batch) < 1:
        raise ValueError(f"batch must be >= 1, got {batch}")
    cfg = cfg if cfg is not None else ActionConfig()
    q = np.asarray(qpos, np.float32)[None]
    p = np.asarray([pair], np.int32)
    rows = np.zeros(int(batch), int)
    _say(progress, "planning (compiles the IK first)", 0, 1)
    plan, _ = jitted_stage_fns(cfg)[0](action_id(action), jnp.asarray(p[rows]), jnp.asarray(q[rows]))
    plan = jax.device_get(plan)
    _say(progress, "planning (compiles the IK first)", 1, 1)
    result = {k: np.asarray(getattr(plan, k))[:1] for k in ("q_way", "grip_way", "feasible", "direction")}
    qvel = np.zeros((1, 12), np.float32) if qvel is None else np.asarray(qvel, np.float32).reshape(1, 12)
    _say(progress, "replaying in MuJoCo C", 0, 1)
    rep = replay_native(action, cfg, p, q, qvel, result, record_every=every)
    _say(progress, "replaying in MuJoCo C", 1, 1)
    return {"frames_xpos": rep["frames_xpos"][0], "frames_xmat": rep["frames_xmat"][0],
            "model": setup(cfg).world.mj_models[int(pair)], "label": bool(rep["label"][0]),
            "object_bodies": (setup(cfg).world.toy_body, setup(cfg).world.obj_body),
            "feasible": bool(result["feasible"][0]), "every": every}


def write_gif(frames: dict[str, Any], out: str | Path, title: str = "", fps: float | None = None,
              progress: Callable[[str, int, int], None] | None = None, width: int = 480,
              height: int = 360) -> Path:
    """Draw ``rollout_frames`` output as a GIF, written atomically: each frame ray cast
    (``perception.rollout_view``) under ``title`` (lines) and the time; an infeasible program
    is marked in red. ``progress("drawing frames", f, F)`` after each frame. Sets
    ``frames["seconds_per_frame"]`` (the drawing's wall time per frame, compile included)."""
    import time

    from PIL import Image, ImageDraw, ImageFont

    t0 = time.perf_counter()
    model = frames["model"]
    xs, rs = frames["frames_xpos"], frames["frames_xmat"]
    bodies = tuple(int(b) for b in frames.get("object_bodies", ()))
    cam = rv.frame_camera(model, xs, bodies, width=width, height=height)
    lines = [x for x in title.split("\n") if x]
    if frames.get("feasible", True):
        lines.append(f"program feasible; shown: its MuJoCo C replay, label {frames['label']}")
    else:
        lines.append("INFEASIBLE: no IK solution, the program is not executed (label False)")
    font = ImageFont.load_default(size=13)
    band = 15 * (len(lines) + 1) + 6
    images: list = []
    _say(progress, "drawing frames", 0, len(xs))
    shade = rv.make_shader(model, cam)
    for f in range(len(xs)):
        im = Image.new("RGB", (width, height + band), (255, 255, 255))
        im.paste(Image.fromarray(np.asarray(shade(xs[f], rs[f]))), (0, band))
        draw = ImageDraw.Draw(im)
        for k, line in enumerate(lines):
            red = line.startswith("INFEASIBLE")
            draw.text((6, 3 + 15 * k), line, fill=(200, 0, 0) if red else (0, 0, 0), font=font)
        draw.text((6, 3 + 15 * len(lines)), f"t = {f * frames['every'] * STEP_SECONDS:.2f} s", fill=(0, 0, 0), font=font)
        images.append(im)
        _say(progress, "drawing frames", f + 1, len(xs))
    fps = fps or 1.0 / (frames["every"] * STEP_SECONDS)
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    atomic_write_bytes(out, buf.getvalue())
    frames["seconds_per_frame"] = (time.perf_counter() - t0) / max(len(xs), 1)
    return Path(out)


def animate_sample(action: str, pair: int, qpos: np.ndarray, out: str | Path, title: str = "",
                   cfg: Any = None, every: int = 10,
                   progress: Callable[[str, int, int], None] | None = None,
                   qvel: np.ndarray | None = None, batch: int = 8) -> dict[str, Any]:
    """``rollout_frames`` then ``write_gif``; returns the frames dict (label, feasible,
    seconds_per_frame, ...); ``progress(phase, done, total)`` hears every phase (see both)."""
    frames = rollout_frames(action, pair, qpos, cfg, every, progress, qvel, batch)
    write_gif(frames, out, title=title, progress=progress)
    return frames


__all__: Sequence[str] = ("rollout_frames", "write_gif", "animate_sample")
