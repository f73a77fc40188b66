"""The contract every stage keeps, and the state a run passes along.

A stage is a module of ``relaff_jax.stages`` with a ``NAME`` and three functions of a ``Run``
(``Stage``; ``relaff_jax.reproduce.run`` composes them in ``constants.STAGES`` order):

- ``status(run) -> Status``: is its output in the run folder ``absent``, ``partial``
  (resumable), ``complete``, ``stale`` (made from other inputs or settings) or ``corrupt``,
  and why; it asks the stage's own package (``relaff_jax.data``, ``learn``, ``report``),
  never reads another stage's files itself;
- ``progress(run) -> float``: the fraction done, from what is on disk (for the progress line);
- ``run(run, forced) -> dict``: (re)make the output, resuming a partial one (``forced``: start
  over); returns what the run log records.

Each stage module also has the one-folder entry its command calls, with a narrower input than
``Run``: the config tree, the input and output folders, a seed and a cluster client
(``generate.generate_one``, ``features.add_features``, ``experiment.experiment_folder``,
``report.report_folder``). ``run(run, forced)`` calls the same function with the run folder's
paths, so ``relaff generate`` and ``relaff reproduce`` run one code path. Every setting is read
from the tree (``run.cfg`` or ``tree``), never passed beside it.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable, Protocol, TextIO, runtime_checkable

from relaff_jax import io as rio
from relaff_jax.errors import UserError
from relaff_jax.cluster import Remote

STATES = ("absent", "partial", "complete", "stale", "corrupt")
RUN_LOG = "run.json"


class ReproduceError(UserError):
    """Bad input, or a run folder a stage cannot use (a missing input, a stale dataset); the
    name the run log's status of a failed run shows."""


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


@dataclasses.dataclass(frozen=True)
class Paths:
    """The run folder's layout: ``run.json``, ``data/<action>/``, ``results/``, ``report/``."""

    root: Path

    @property
    def log(self) -> Path:
        return self.root / RUN_LOG

    @property
    def data(self) -> Path:
        return self.root / "data"

    @property
    def results(self) -> Path:
        return self.root / "results"

    @property
    def report(self) -> Path:
        return self.root / "report"

    def dataset(self, action: str) -> Path:
        return self.data / action


class Reporter(Protocol):
    """Where a stage says what it does (``reproduce.progress.Progress``, or ``Silent``)."""

    def set(self, detail: str | None = None, fraction: float | None = None) -> None: ...

    def message(self, text: str) -> None: ...


class Silent:
    """A ``Reporter`` that says nothing (a run built only to read statuses)."""

    def set(self, detail: str | None = None, fraction: float | None = None) -> None:
        pass

    def message(self, text: str) -> None:
        pass


@dataclasses.dataclass(frozen=True)
class Hooks:
    """Stand-ins a caller (a test, a benchmark) gives ``reproduce`` instead of the tree's own
    simulation and perception; None: the tree's (``generate.rollout_factory_for``,
    ``features.factories_for``).

    rollout_factory(action, batch) -> (rollout_fn, config_dict, object_names);
    feature_factory(seed) -> (compute_fn, config_dict), with feature_config(seed) -> that
    config_dict (without building the perception); stream: where the progress line goes
    (default stderr). With a cluster client the factories must be picklable."""

    rollout_factory: Callable | None = None
    feature_factory: Callable | None = None
    feature_config: Callable | None = None
    stream: TextIO | None = None

    def __post_init__(self):
        if self.feature_factory is not None and self.feature_config is None:
            raise ReproduceError("a custom feature_factory needs feature_config (its config_dict per seed)")


@dataclasses.dataclass
class Run:
    """One ``reproduce`` invocation: folder, resolved config tree, seed, factories, log."""

    paths: Paths
    preset: str
    cfg: Any  # config.RunConfig
    seed: int
    jobs: int
    force: tuple[str, ...]
    progress: Reporter
    rollout_factory: Callable  # (action, batch) -> (rollout_fn, config_dict, object_names)
    feature_factory: Callable  # (seed) -> (compute_fn, config_dict)
    feature_config: Callable  # (seed) -> config_dict of feature_factory
    log: dict  # the run log (run.json): ``seeds`` of every stage, ``versions``, ``timings``
    entry: dict  # this invocation's entry of ``log["runs"]``
    client: Any = None  # a distributed.Client: chunks and sweep blocks run on its cluster
    # statuses read every chunk even where a dataset's status manifest vouches for it
    # (``data.status.write_manifest``): the reference of the metadata path (benchmarks, tests)
    verify: bool = False

    def remote(self, factory: Callable, *args: Any) -> Callable:
        """The function ``factory(*args)[0]`` shipped to the cluster's workers as its recipe
        (``cluster.Remote``: each worker builds and compiles it once)."""
        return Remote(factory, *args, pick=0)

    def save(self) -> None:
        rio.atomic_write_json(self.paths.log, self.log)


@runtime_checkable
class Stage(Protocol):
    """What ``reproduce`` needs of a stage module (``isinstance(module, Stage)`` checks it)."""

    NAME: str

    def status(self, run: Run) -> Status: ...

    def progress(self, run: Run) -> float: ...

    def run(self, run: Run, forced: bool) -> dict: ...
