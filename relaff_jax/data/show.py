"""``relaff show``'s stage: one sample of a dataset drawn as the simulated Kinect sees it (PNG),
or its motor program replayed in MuJoCo C and ray cast (GIF, ``sim.animate``).

    show_sample(tree, folder, index, out, rollout=False, progress=None) -> message

Reads the dataset (``load.load_dataset``, without features), checks ``index``, and hands the
sample's pair and settled pose to ``perception.from_sim.show_scene`` or ``sim.animate``.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from relaff_jax.errors import UserError
from relaff_jax.data.load import load_dataset
from relaff_jax.data.store import read_sidecar
from relaff_jax.sim.object_library import use_recorded
from relaff_jax.perception import from_sim
from relaff_jax.sim import world as wd
from relaff_jax.config import override_under
from relaff_jax.data import audit as A
from relaff_jax.sim.animate import animate_sample
from relaff_jax.sim.reach_screen import PLAN_CHUNK  # generation plans in calls of at most this many rows


def show_sample(tree: Any, folder: str | os.PathLike, index: int, out: str | os.PathLike, *,
                rollout: bool = False, progress: Any = None, action_overrides: Any = None,
                say: Any = None) -> str:
    """Draw sample ``index`` of the dataset ``folder`` into ``out`` with the ``RunConfig``
    ``tree``'s perception (the PNG) or the dataset's recorded action config (the GIF); return
    what was written. ``action_overrides`` ({"lift_height": 0.3}: the ``--set action.*`` keys)
    change the recorded action config of the GIF's replay.
    ``say(text)``: told what the PNG's silent part does (building the world, compiling).
    ``progress``: the GIF's phase bars (``sim.animate.animate_sample``)."""
    out = Path(out)
    if rollout and out.suffix.lower() != ".gif":
        raise UserError(f"--rollout writes a GIF; give --out a .gif name, not {out.name}")

    ds = load_dataset(folder, features=False)
    use_recorded(read_sidecar(Path(folder)))  # its pair indices index the pairs of the objects it was made of
    n = len(ds["label"])
    if not 0 <= index < n:
        raise UserError(f"--index {index} out of range: the dataset has {n} samples")
    label = bool(ds["label"][index])
    title = (f"{ds['action']} sample {index}: {ds['toy'][index]} + {ds['other'][index]}, "
             f"{ds['relation'][index]}, label {label}")
    pair, qpos = int(ds["pair"][index]), ds["qpos_settled"][index]
    if rollout:
        return _rollout_gif(folder, ds, index, out, progress, action_overrides or {})
    if say is not None:  # the inputs are checked; what follows compiles for tens of seconds: say so
        say(f"sample {index}: building the world and compiling the camera (tens of seconds the first time)...")

    if "feasible" in ds:  # whether the arm could run the program: a negative label may be reach, not relation
        title += f", program {'feasible' if bool(ds['feasible'][index]) else 'infeasible (out of reach)'}"
    else:
        title += ", program feasibility not recorded"
    path = from_sim.show_scene(wd.build_world(tree.action.phys), pair, qpos, out,
                               from_sim.show_key(int(ds["rollout_id"][index])), cfg=tree.perception, title=title)
    return f"wrote {path}"


ENGINE_NAMES = {"native": "MuJoCo C (native engine)", "mjx": "MJX"}


def _rollout_gif(folder: Any, ds: dict, index: int, out: Path, progress: Any, overrides: dict) -> str:
    """The GIF of sample ``index``: replayed with the dataset's recorded action config and, for
    a native dataset, its re-settled velocities (``data.audit``), so that the replay is the
    engine's reference and its label the stored one."""
    import numpy as np

    meta = read_sidecar(Path(folder))
    cfg = override_under(A.action_config(meta), overrides, "action.")
    engine = str(meta.get("engine"))
    row = {k: np.asarray(ds[k])[index:index + 1] for k in ("pair", "qpos0", "qpos_settled", "intended")}
    qvel, same = A.settled_velocities(cfg, meta, row, None)
    label = bool(ds["label"][index])
    title = (f"{ds['action']} sample {index}: {ds['toy'][index]} + {ds['other'][index]}, {ds['relation'][index]}\n"
             f"dataset label {label}, simulated by {ENGINE_NAMES.get(engine, engine)}")
    frames = animate_sample(str(ds["action"]), int(row["pair"][0]), row["qpos_settled"][0], out, title=title,
                            cfg=cfg, progress=progress, qvel=qvel[0], batch=min(int(meta["batch"]), PLAN_CHUNK))
    if overrides:
        why = "the dataset's settled state with the --set action keys " + ", ".join(sorted(overrides))
    elif bool(same[0]):
        why = "the same settled state and plan: the native engine's reference"
    else:
        why = "MJX's settled positions at rest, replayed in C (MJX and C agree on ~98 % of labels)"
    return (f"wrote {out}: {len(frames['frames_xpos'])} frames, {frames['seconds_per_frame']:.2f} s per frame; "
            f"program feasible {frames['feasible']}; label in the MuJoCo C replay {frames['label']} "
            f"(dataset: {label}, {ENGINE_NAMES.get(engine, engine)}; replay from {why})")


__all__ = ["show_sample"]
