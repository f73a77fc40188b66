"""Example scenes of the report: what the robot saw, drawn by the perception stage.

Takes dataset folders ``{action: DIR}`` whose samples keep their scenes (``pair``,
``qpos_settled``); ``example_scenes`` writes ``per_action`` pictures per action (positives
and negatives alternating) under ``out`` and returns ``(action, relative path, caption)``;
``examples_beside`` draws them in a process of their own while the caller writes the rest of
the report (the drawing is one core's matplotlib and the analysis another's). JAX, MuJoCo and
the perception stage load only when pictures are drawn.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from relaff_jax.report import folder as F
from relaff_jax.data import load_dataset
from relaff_jax.perception import from_sim
from relaff_jax.sim import world as wd
from relaff_jax.data.store import read_sidecar
from relaff_jax.sim.object_library import use_recorded


def example_scenes(data_dirs: Mapping[str, str | os.PathLike], out: Path, per_action: int) -> list[tuple[str, str, str]]:
    """Draw ``per_action`` example scenes per action (positives and negatives alternating, in
    rollout order) with ``perception.from_sim.show_scene``; returns ``(action, file name, caption)``.
    Datasets without the scene fields (``pair``, ``qpos_settled``) get none."""
    if per_action < 1:
        return []
    import jax

    shown: list[tuple[str, str, str]] = []
    for action, d in data_dirs.items():
        ds = load_dataset(d, features=False)
        if not {"pair", "qpos_settled"} <= set(ds):
            continue
        use_recorded(read_sidecar(Path(d)))  # its pair indices refer to the objects it records
        world = wd.build_world()  # cached per object set
        label = np.asarray(ds["label"], bool)
        pos, neg = list(np.flatnonzero(label)), list(np.flatnonzero(~label))
        order = [x for pair in zip(pos, neg) for x in pair] + pos[len(neg):] + neg[len(pos):]
        for i in order[:per_action]:
            rid = int(ds["rollout_id"][i]) if "rollout_id" in ds else int(ds["rollout"][i])
            caption = (f"{action}: {ds['toy'][i]} + {ds['other'][i]}, {ds['relation'][i]}, "
                       f"{'positive' if label[i] else 'negative'} (sample {i})")
            name = F.example(action, i)
            from_sim.show_scene(world, int(ds["pair"][i]), np.asarray(ds["qpos_settled"][i]), out / name,
                                jax.random.PRNGKey(rid % 2**31), title=caption)
            shown.append((action, f"{out.name}/{name}", caption))
    return shown


MIN_CORES = 2  # below this a second process would only take the report's core


class Drawing:
    """Example scenes being drawn (``examples_beside``): call it for their list (it waits, and
    raises the drawing's error; if the drawing process died, it draws them here instead);
    ``cancel()`` stops a drawing process."""

    def __init__(self, draw: Callable[[], list] | None = None, pool=None, job=None):
        self.draw, self.pool, self.job = draw, pool, job

    def __call__(self) -> list[tuple[str, str, str]]:
        if self.pool is None:
            return self.draw()
        from concurrent.futures.process import BrokenProcessPool

        try:
            return self.job.result()
        except BrokenProcessPool:  # the process died (killed, out of memory): draw here instead
            print("report: the example scenes' drawing process ended abruptly; drawing them in this process",
                  file=sys.stderr, flush=True)
            return self.draw()
        finally:
            self.pool.shutdown(wait=True, cancel_futures=True)

    def cancel(self) -> None:
        if self.pool is not None:
            # a pool that has shut down (or broken) keeps None here, not a dict
            for proc in list((getattr(self.pool, "_processes", None) or {}).values()):
                proc.terminate()  # each picture is written atomically: none is left half-written
            self.pool.shutdown(wait=False, cancel_futures=True)


def examples_beside(data_dirs: Mapping[str, str | os.PathLike], out: Path, per_action: int,
                    cores: int | None = None) -> Drawing:
    """Start ``example_scenes(data_dirs, out, per_action)`` in a spawned process (on ``cores``
    >= ``MIN_CORES``, default this process's; else nothing starts and calling the result draws
    here). The process loads this process's plugin files and uses its compilation cache (the
    environment carries it); the pictures are the same files either way."""
    from relaff_jax.data.audit_replay import default_jobs

    cores = default_jobs() if cores is None else cores
    if per_action < 1 or cores < MIN_CORES:
        return Drawing(lambda: example_scenes(data_dirs, out, per_action))
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from relaff_jax.plugins import loaded_files

    pool = ProcessPoolExecutor(1, mp_context=get_context("spawn"))
    job = pool.submit(_in_child, loaded_files(), {a: str(d) for a, d in data_dirs.items()}, str(out), per_action)
    return Drawing(lambda: example_scenes(data_dirs, out, per_action), pool=pool, job=job)


def _in_child(plugins, data_dirs: dict[str, str], out: str, per_action: int) -> list[tuple[str, str, str]]:
    from relaff_jax.plugins import load_files

    load_files(plugins)  # (path, sha256) pairs: a file changed since the parent read it is refused
    return example_scenes({a: Path(d) for a, d in data_dirs.items()}, Path(out), per_action)
