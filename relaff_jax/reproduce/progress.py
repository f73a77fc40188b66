"""One progress line for a whole ``relaff reproduce`` run: stage, progress, elapsed, ETA.

A stage's progress comes from its ``progress(run)`` probe (what it has written to disk), read
by a background thread, so it is right after a resume. Before a stage has measurable
progress its time comes from a cost model (``COST``, seconds on the project's 2-core
machine, docs/reproduce.md); once it moves, the measured rate takes over gradually, so the
estimate does not jump when the first few percent happen to be fast or slow.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Any, Callable, Mapping

import numpy as np

from relaff_jax.constants import STAGES
from relaff_jax.learn import forests_per_space

COST = {
    "sim_compile": 150.0,  # first rollout call: place, settle, plan and simulate programs (all actions)
    "rollouts_per_sample": 2.5,  # rollouts simulated per selected sample (positive rate, matching)
    # the same when only feasible rollouts may be selected (dataset.population=feasible): the
    # paper preset's 448,512 rollouts for 9 x 10,000 samples (2026-12-05, docs/reproduce.md)
    "rollouts_per_sample_feasible": 5.0,
    "rollouts_per_s": 5.0,  # settle + plan + the feasible 3.3 s motor programs (docs/actions.md)
    # the same with dataset.engine=native: C settle, reach screen, C execution; the paper
    # preset's whole data stage at batch 1,024, 448,512 rollouts in 2,977 s (2026-12-05)
    "rollouts_per_s_native": 150.0,
    "feature_compile": 40.0,
    "feature_scenes_per_s": 110.0,  # the paper preset's features stage: 90,000 scenes in 811 s (2026-12-05)
    # a forest of ~100 trees, fit + predict, fast engine: 5.4 ms in the quick preset, 4.2 in the
    # study preset (541 s for <= 260,154 forests on two workers), 2.6-3.4 in the paper preset's
    # 2,850-3,715 s (2026-12-02/03, docs/reproduce.md); it was 10 ms, 3x the paper run
    "cpu_s_per_fit": 0.004,
    "cpu_s_per_fit_sklearn": 0.15,  # the same with experiment.forest.engine=sklearn
    # the same with the compiled engine: the paper preset's experiment, 2,207,079 forests (the
    # count before the run) in 1,471 s on two workers (2026-12-05, docs/reproduce.md)
    "cpu_s_per_fit_compiled": 0.0013,
    "report_fixed": 60.0,
    # the report's resampling grows with the sweep: 255 s for the paper preset's 2,207,079
    # forests (2026-12-05), 33 s for the study preset's <= 260,154 (2026-12-02): ~1.2e-4 s each
    "report_s_per_forest": 1.2e-4,
    "report_per_example": 1.5,
}
TRUST_AFTER = 0.25  # fraction of a stage after which the measured rate alone gives its ETA


def fmt_time(s: float | None) -> str:
    """``m:ss`` or ``h:mm:ss``; ``--:--`` when unknown."""
    if s is None or not np.isfinite(s):
        return "--:--"
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def estimate_seconds(cfg: Any, jobs: int, cpus: int) -> dict[str, float]:
    """Rough wall time per stage of a ``RunConfig`` from ``COST``."""
    n, a = cfg.dataset.n_samples, len(cfg.reproduce.actions)
    rate = COST["rollouts_per_s_native" if cfg.dataset.engine == "native" else "rollouts_per_s"]
    per_sample = COST["rollouts_per_sample_feasible" if cfg.dataset.population == "feasible" else "rollouts_per_sample"]
    gen = COST["sim_compile"] + a * n * per_sample / rate
    feat = COST["feature_compile"] + a * n / COST["feature_scenes_per_s"]
    fits = sum(forests_per_space(cfg.experiment, a, s) for s in cfg.reproduce.spaces)
    per_fit = COST[{"sklearn": "cpu_s_per_fit_sklearn", "compiled": "cpu_s_per_fit_compiled"}.get(
        cfg.experiment.forest.engine, "cpu_s_per_fit")]
    exp = fits * per_fit / max(1, min(jobs, cpus))
    rep = max(COST["report_fixed"], fits * COST["report_s_per_forest"]) \
        + a * cfg.reproduce.examples_per_action * COST["report_per_example"]
    return {"generate": gen, "features": feat, "experiment": exp, "report": rep}


def human_time(s: float) -> str:
    """A duration for a message: ``m:ss`` up to an hour, then hours, days or years."""
    if s < 3600:
        return fmt_time(s)
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("hours", 3600)):
        if s >= 2 * size or unit == "hours":
            return f"{s / size:,.0f} {unit}" if s >= 10 * size else f"{s / size:.1f} {unit}"
    return fmt_time(s)  # pragma: no cover


def generate_seconds(n_samples: int, engine: str = "mjx") -> float:
    """The cost model's wall time for one balanced dataset of ``n_samples`` (compile included)."""
    rate = COST["rollouts_per_s_native" if engine == "native" else "rollouts_per_s"]
    return COST["sim_compile"] + n_samples * COST["rollouts_per_sample"] / rate


def sample_bound(n_samples: int, max_rollouts: int, batch: int, engine: str = "mjx",
                 names: tuple[str, str] = ("dataset.n_samples", "dataset.max_rollouts")) -> str | None:
    """Why ``n_samples`` balanced samples cannot come out of the rollout cap, or None.

    A balanced dataset of N samples needs N distinct rollouts at the least (about
    ``COST["rollouts_per_sample"]`` times as many in practice); the generator stops at
    ``max_rollouts`` rounded up to whole chunks of ``batch``. ``names``: how the message calls
    the two settings (the CLI's options, or the config keys)."""
    cap = -(-int(max_rollouts) // int(batch)) * int(batch)
    if n_samples <= cap:
        return None
    rate = COST["rollouts_per_s_native" if engine == "native" else "rollouts_per_s"]
    return (f"{names[0]} {n_samples:,} cannot be reached: a balanced dataset of N samples needs at least N "
            f"rollouts, and {names[1]} caps them at {cap:,}; the ~{n_samples * COST['rollouts_per_sample']:,.0f} "
            f"rollouts it would take run ~{human_time(generate_seconds(n_samples, engine))} at ~{rate:g} "
            f"rollouts/s (engine {engine}, docs/reproduce.md). Lower {names[0]} or raise {names[1]}")


def stage_left(model: float, spent: float, f: float, first: tuple[float, float] | None, now: float) -> float:
    """Seconds left in a stage at fraction ``f`` after ``spent`` seconds.

    ``model``: the cost model's seconds for the whole stage; ``first``: (time, fraction) when
    progress first moved (the rate excludes compiling and the work of a killed run). The
    measured estimate is blended in with weight rising from 0 to 1 over ``TRUST_AFTER`` of
    the stage.
    """
    model_left = max(model * (1 - f) - spent, model * (1 - f) * 0.1)
    if first is None or f <= first[1] or now - first[0] < 5:
        return model_left
    measured_left = (now - first[0]) * (1 - f) / (f - first[1])
    w = min(1.0, (f - first[1]) / TRUST_AFTER)
    return w * measured_left + (1 - w) * model_left


# What a stage does before its first measurable progress (shown until the fraction moves).
STARTING = {"generate": "building the world, compiling the motor program and settling the first chunk",
            "features": "compiling the camera and the descriptors",
            "experiment": "loading the datasets and fitting the source predictors",
            "report": "analysing the results"}


class Progress:
    """The progress line. On a terminal it is redrawn in place; otherwise a line is printed
    when the stage's item changes and every ``every`` seconds."""

    def __init__(self, estimates: Mapping[str, float], enabled: bool = True, stream=None, every: float = 30.0):
        self.estimates = dict(estimates)
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.every = every
        self.t0 = time.perf_counter()
        self.stage = ""
        self.stage_t0 = self.t0
        self.detail = ""
        self.probe: Callable[[], float] | None = None
        self.fraction = 0.0
        self._first: tuple[float, float] | None = None
        self._last_detail = None
        self._last_print = 0.0
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    # -- control
    def start(self) -> None:
        if self.enabled:
            self._thread = threading.Thread(target=self._loop, daemon=True)
            self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()

    def begin(self, stage: str, probe: Callable[[], float] | None = None) -> None:
        with self._lock:
            self.stage, self.stage_t0, self.probe, self.fraction, self.detail = stage, time.perf_counter(), probe, 0.0, ""
            self._first = None

    def set(self, detail: str | None = None, fraction: float | None = None) -> None:
        with self._lock:
            if detail is not None:
                self.detail = detail
            if fraction is not None:
                self._set_fraction(fraction)

    def _set_fraction(self, f: float) -> None:
        """Record progress (caller holds the lock) and when it first moved."""
        f = min(max(float(f), 0.0), 1.0)
        if self._first is None and f > self.fraction:
            self._first = (time.perf_counter(), f)
        self.fraction = f

    def message(self, text: str) -> None:
        """A permanent line (a stage's result) above the progress line."""
        if not self.enabled:
            return
        with self._lock:
            self.stream.write(("\r\033[K" if self.tty else "") + text + "\n")
            self.stream.flush()

    # -- rendering
    def eta(self) -> float | None:
        """Seconds left: the current stage (``stage_left``) plus the model's later stages."""
        if self.stage not in STAGES:
            return None
        i = STAGES.index(self.stage)
        now = time.perf_counter()
        left = stage_left(self.estimates.get(self.stage, 0.0), now - self.stage_t0, self.fraction, self._first, now)
        return left + sum(self.estimates.get(s, 0.0) for s in STAGES[i + 1:])

    def done(self, stage: str) -> None:
        """``stage`` finished (ran or skipped): nothing of it is left in the estimate."""
        with self._lock:
            self.estimates[stage] = 0.0
            if stage == self.stage:
                self._set_fraction(1.0)

    def line(self) -> str:
        i = STAGES.index(self.stage) + 1 if self.stage in STAGES else 0
        now = time.perf_counter()
        detail = self.detail
        if self._first is None and self.fraction == 0.0 and STARTING.get(self.stage):
            # nothing measured yet: say what takes this time (compiles, the first chunk), not a silent 0 %
            detail = f"{detail}: {STARTING[self.stage]}, {fmt_time(now - self.stage_t0)}" if detail else \
                f"{STARTING[self.stage]}, {fmt_time(now - self.stage_t0)}"
        eta = fmt_time(self.eta())
        if self._first is None and self.fraction < 1.0:
            eta += " (cost model)"  # no rate measured in this stage yet
        return (f"reproduce [{i}/{len(STAGES)} {self.stage}] {detail} {100 * self.fraction:3.0f}% | "
                f"elapsed {fmt_time(now - self.t0)} | ETA {eta}")

    def _loop(self) -> None:
        while not self._stop.wait(1.0 if self.tty else 2.0):
            self.tick()

    def tick(self) -> None:
        probe = self.probe
        if probe is not None:
            try:
                f = float(probe())
                with self._lock:
                    self._set_fraction(f)
            except (OSError, ValueError, KeyError):  # a file caught mid-replace: try again next tick
                pass
        with self._lock:
            text = self.line()
            now = time.perf_counter()
            if self.tty:
                self.stream.write("\r\033[K" + text)
                self.stream.flush()
            elif (self.stage, self.detail) != self._last_detail or now - self._last_print >= self.every:
                self.stream.write(text + "\n")
                self.stream.flush()
                self._last_detail, self._last_print = (self.stage, self.detail), now
