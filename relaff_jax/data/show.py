"""``relaff show``'s stage: one sample of a dataset drawn as the simulated Kinect sees it (PNG),
or its motor program replayed in MuJoCo C (GIF).

    show_sample(tree, folder, index, out, rollout=False, progress=None) -> message

Reads the dataset (``load.load_dataset``, without features), checks ``index``, and hands the
sample's pair and settled pose to ``perception.from_sim.show_scene`` or ``sim.animate``.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from relaff_jax.errors import UserError


def show_sample(tree: Any, folder: str | os.PathLike, index: int, out: str | os.PathLike, *,
                rollout: bool = False, progress: Any = None, say: Any = None) -> str:
    """Draw sample ``index`` of the dataset ``folder`` into ``out`` with the ``RunConfig``
    ``tree`` (its perception for the PNG, its action for the GIF); return what was written.
    ``say(text)``: told what the PNG's silent part does (building the world, compiling).
    ``progress``: the GIF's phase bars (``sim.animate.animate_sample``)."""
    from relaff_jax.data.load import load_dataset

    out = Path(out)
    if rollout and out.suffix.lower() != ".gif":
        raise UserError(f"--rollout writes a GIF; give --out a .gif name, not {out.name}")
    ds = load_dataset(folder, features=False)
    n = len(ds["label"])
    if not 0 <= index < n:
        raise UserError(f"--index {index} out of range: the dataset has {n} samples")
    label = bool(ds["label"][index])
    title = (f"{ds['action']} sample {index}: {ds['toy'][index]} + {ds['other'][index]}, "
             f"{ds['relation'][index]}, label {label}")
    pair, qpos = int(ds["pair"][index]), ds["qpos_settled"][index]
    if rollout:
        from relaff_jax.sim.animate import animate_sample

        frames = animate_sample(str(ds["action"]), pair, qpos, out, title=title, cfg=tree.action, progress=progress)
        return (f"wrote {out}: {len(frames['frames_xpos'])} frames; feasible {frames['feasible']}, "
                f"label in the MuJoCo C replay {frames['label']} (dataset: {label}, MJX)")
    if say is not None:  # the inputs are checked; what follows compiles for tens of seconds: say so
        say(f"sample {index}: building the world and compiling the camera (tens of seconds the first time)...")
    from relaff_jax.perception import from_sim
    from relaff_jax.sim import world as wd

    if "feasible" in ds:  # whether the arm could run the program: a negative label may be reach, not relation
        title += f", program {'feasible' if bool(ds['feasible'][index]) else 'infeasible (out of reach)'}"
    else:
        title += ", program feasibility not recorded"
    path = from_sim.show_scene(wd.build_world(tree.action.phys), pair, qpos, out,
                               from_sim.show_key(int(ds["rollout_id"][index])), cfg=tree.perception, title=title)
    return f"wrote {path}"


__all__ = ["show_sample"]
