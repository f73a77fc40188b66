"""The contract every stage of ``relaff reproduce`` keeps, and the state a run passes along.

A stage is a module with a ``NAME`` and three functions of a ``Run``:

- ``status(run) -> Status``: is its output in the run folder ``absent``, ``partial``
  (resumable), ``complete``, ``stale`` (made from other inputs or settings) or ``corrupt``,
  and why; it asks the stage's own package (``relaff_jax.data``, ``learn``, ``report``),
  never reads another stage's files itself;
- ``progress(run) -> float``: the fraction done, from what is on disk (for the progress line);
- ``run(run, forced) -> dict``: (re)make the output, resuming a partial one (``forced``: the
  stage was asked for by ``--force``); returns what the run log records.

``relaff_jax.reproduce.run`` composes them: a complete stage is skipped unless forced.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable

from relaff_jax import io as rio
from relaff_jax.reproduce.folder import Paths
from relaff_jax.reproduce.progress import Progress

STATES = ("absent", "partial", "complete", "stale", "corrupt")


@dataclasses.dataclass(frozen=True)
class Status:
    """A stage's output on disk: ``state`` in ``STATES`` and a one-line reason."""

    state: str
    why: str = ""

    def __post_init__(self):
        if self.state not in STATES:
            raise ValueError(f"unknown stage state {self.state!r}; expected one of {STATES}")

    @staticmethod
    def combine(parts: dict[str, "Status"]) -> "Status":
        """One status for a stage made of parts (e.g. one dataset per action): complete only
        if every part is; otherwise the first part that is not, named."""
        started = any(p.state != "absent" for p in parts.values())
        for name, st in parts.items():
            if st.state != "complete":
                # an action not begun while others are done: the stage as a whole is partial
                state = "partial" if st.state == "absent" and started else st.state
                return Status(state, f"{name}: {st.why}")
        return Status("complete", f"{len(parts)} of {len(parts)} complete")


@dataclasses.dataclass
class Run:
    """One ``reproduce`` invocation: folder, resolved config tree, seed, hooks, log."""

    paths: Paths
    preset: str
    cfg: Any  # runconfig.RunConfig
    seed: int
    jobs: int
    force: tuple[str, ...]
    progress: Progress
    rollout_factory: Callable  # (action, batch) -> (rollout_fn, config_dict, object_names)
    feature_factory: Callable  # (seed) -> (compute_fn, config_dict)
    feature_config: Callable  # (seed) -> config_dict of feature_factory
    log: dict
    entry: dict
    client: Any = None  # a distributed.Client: chunks and sweep blocks run on its cluster

    def remote(self, factory: Callable, *args: Any) -> Callable:
        """The function ``factory(*args)[0]`` shipped to the cluster's workers as its recipe
        (``cluster.Remote``: each worker builds and compiles it once)."""
        from relaff_jax.cluster import Remote

        return Remote(factory, *args, pick=0)

    def save(self) -> None:
        rio.atomic_write_json(self.paths.log, self.log)
