"""One dataset chunk or one feature chunk as a task: computed, written, summarised.

Takes the chunk's recipe (the rollout or feature function, its index, seed/batch and, for
features, the chunk's own samples) and the *pending* folder; writes the chunk there
atomically (``store.write_chunk``) and returns only what the driver needs to go on: labels
``(batch,) bool`` and COG distances ``(batch,) metres`` of a dataset chunk (the selection),
the schema of its arrays, and ``feasible`` (the selection's population) and ``settled`` (its
rest rule) when they have them. The same functions run in the driver (no cluster) or on a Dask
worker (``relaff_jax.cluster.Ordered``).

Pending chunks (``chunks/.pending/chunk_K``, ``features/.pending/chunk_F``) may finish in any
order; the driver alone moves them into place (``promote``, one ``os.replace``) in index
order and writes the sidecar, so ``chunks/`` stays a contiguous prefix, exactly what a run
without a cluster leaves. A pending chunk found on a rerun (the driver was killed while it
ran) is taken as it is: it holds the same bits a new simulation would give. A task run twice
(a retry after a lost worker) finds its chunk already there and only reads it.
"""
from __future__ import annotations

import os
import shutil
import threading
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from relaff_jax.data.store import CHUNK_RE, check_rollout_ids, chunk_path, read_chunk, write_chunk
from relaff_jax.data.validate import check_schema, schema_of, standardize_features, standardize_rollouts

PENDING = ".pending"


def _write_once(path: Path, arrays: Mapping[str, np.ndarray], extra: Mapping[str, Any]) -> None:
    try:
        write_chunk(path, arrays, extra)
    except OSError:
        if not path.is_dir():  # not a twin of this task that finished first
            raise


def chunk_key(seed: int, k: int):
    """The PRNG key of dataset chunk ``k``: ``fold_in(PRNGKey(seed), k)``."""
    import jax

    return jax.random.fold_in(jax.random.PRNGKey(seed), k)


def rollout_chunk(rollout_fn: Callable, seed: int, k: int, batch: int, object_names: Sequence[str] | None,
                  pending: str, ref: Mapping[str, list] | None = None,
                  ahead: "PrepareAhead | None" = None) -> dict[str, Any]:
    """Simulate dataset chunk ``k`` (key ``chunk_key(seed, k)``) into ``pending``;
    returns ``label``, ``cog_distance`` and ``schema`` (arrays without ``rollout``). A chunk
    whose schema differs from ``ref`` (the earlier chunks', when known) is not written.
    ``ahead`` (the driver without a cluster): chunk ``k``'s first half comes from it, and chunk
    ``k + 1``'s is begun there before chunk ``k`` executes."""
    path = chunk_path(Path(pending), k)
    if path.is_dir():
        return read_rollout_chunk(path, k, batch)
    if ahead is None:
        out = rollout_fn(chunk_key(seed, k), batch)
    else:
        prepared = ahead.take(k)
        ahead.begin(k + 1)
        out = rollout_fn.execute(prepared)
    arrays = standardize_rollouts(out, batch, object_names)
    schema = schema_of(arrays)
    check_schema(f"chunk {k} from rollout_fn", schema, ref)
    arrays["rollout"] = k * batch + np.arange(batch, dtype=np.int64)
    _write_once(path, arrays, {"chunk": k, "batch": batch, "positives": int(arrays["label"].sum())})
    return _for_driver(arrays, schema)


class PrepareAhead:
    """Prepares dataset chunks one ahead on a background thread, for a rollout function with
    two halves (``rollout_fn.prepare(key, batch)``, ``rollout_fn.execute(prepared)``, e.g.
    ``sim.rollouts.RolloutFn``): while chunk ``k`` executes in the driver (MuJoCo C on its
    thread pool, with Python between its steps), chunk ``k + 1`` is sampled, settled and
    planned beside it, so that both cores stay busy. The halves are the same calls on the same
    keys as ``rollout_fn(key, batch)``: a chunk's bits do not depend on this.

    ``begin(j)`` starts chunk ``j``'s first half (nothing past ``limit`` or already begun);
    ``take(j)`` waits for it and raises what it raised (one not begun is prepared in the caller);
    ``close()`` drops what is not taken: the first half writes nothing, so a chunk begun past
    the stopping point costs only its CPU (at most one per dataset), and a thread still
    running then is a daemon that finishes on its own without holding up the process."""

    def __init__(self, rollout_fn: Callable, seed: int, batch: int, limit: int):
        self.fn, self.seed, self.batch, self.limit = rollout_fn, seed, batch, int(limit)
        self.jobs: dict[int, tuple[threading.Thread, dict]] = {}

    @staticmethod
    def supports(rollout_fn: Any) -> bool:
        return callable(getattr(rollout_fn, "prepare", None)) and callable(getattr(rollout_fn, "execute", None))

    def begin(self, j: int) -> None:
        if j >= self.limit or j in self.jobs:
            return
        box: dict = {}

        def work():
            try:
                box["value"] = self.fn.prepare(chunk_key(self.seed, j), self.batch)
            except BaseException as e:  # noqa: BLE001 - raised again by take()
                box["error"] = e

        thread = threading.Thread(target=work, name=f"prepare-chunk-{j}", daemon=True)
        thread.start()
        self.jobs[j] = (thread, box)

    def take(self, j: int) -> Any:
        if j not in self.jobs:  # the first chunk of a run: prepared here
            return self.fn.prepare(chunk_key(self.seed, j), self.batch)
        thread, box = self.jobs.pop(j)
        thread.join()
        if "error" in box:
            raise box["error"]
        return box["value"]

    def close(self) -> None:
        self.jobs.clear()


def read_rollout_chunk(path: Path, k: int, batch: int) -> dict[str, Any]:
    """``rollout_chunk``'s summary of a chunk already on disk (verified)."""
    arrays, _ = read_chunk(path)
    check_rollout_ids(path, arrays, k, batch)
    arrays.pop("rollout")
    return _for_driver(arrays, schema_of(arrays))


def _for_driver(arrays: Mapping[str, Any], schema: Mapping[str, list]) -> dict[str, Any]:
    """What the driver's selection reads of a chunk (``feasible``, ``settled`` when the rollouts have them)."""
    out = {"label": arrays["label"], "cog_distance": arrays["cog_distance"], "schema": schema}
    for k in ("feasible", "settled"):
        if k in arrays:
            out[k] = arrays[k]
    return out


def feature_chunk(compute_fn: Callable, samples: Mapping[str, np.ndarray], f: int, batch: int, lo: int, hi: int,
                  pending: str, ref: Mapping[str, list] | None = None, writer: Any = None) -> dict[str, Any]:
    """Features of selected samples ``[lo, hi)`` (``samples``: their ``batch`` padded rows) into
    ``pending`` as feature chunk ``f``; returns its ``schema`` (not written if it differs
    from ``ref``). With ``writer`` (a one-thread ``concurrent.futures`` executor, in the
    driver only) the write runs there, so that the next chunk's perception overlaps it, and
    ``written`` is its future: the chunk is on disk once that future is done."""
    got = feature_piece(compute_fn, samples, f, batch, lo, hi, pending, ref)
    if "arrays" not in got:
        return got
    return {"schema": got["schema"], **write_piece(Path(pending), f, got, writer)}


def feature_piece(compute_fn: Callable, samples: Mapping[str, np.ndarray], f: int, batch: int, lo: int, hi: int,
                  pending: str, ref: Mapping[str, list] | None = None) -> dict[str, Any]:
    """``feature_chunk``'s computation without its write: ``{"schema", "arrays", "extra"}``, or
    ``{"schema"}`` alone when ``pending`` already holds chunk ``f``. What the driver's compute
    threads run (``data.features``), so that the one writer writes the chunks in index order."""
    path = chunk_path(Path(pending), f)
    if path.is_dir():
        arrays, _ = read_chunk(path)
        return {"schema": schema_of(arrays)}
    arrays = standardize_features(compute_fn(dict(samples)), batch, set(samples))
    arrays = {k: a[: hi - lo] for k, a in arrays.items()}
    check_schema(f"feature chunk {f}", schema_of(arrays), ref)
    return {"schema": schema_of(arrays), "arrays": arrays, "extra": {"chunk": f, "batch": batch, "start": lo, "stop": hi}}


def write_piece(pending: Path, f: int, got: Mapping[str, Any], writer: Any = None) -> dict[str, Any]:
    """Write ``feature_piece``'s chunk ``f`` into ``pending``: on ``writer`` (then ``{"written":
    future}``) or here (``{}``)."""
    path = chunk_path(pending, f)
    if writer is not None:
        return {"written": writer.submit(_write_once, path, got["arrays"], got["extra"])}
    _write_once(path, got["arrays"], got["extra"])
    return {}


def promote(pending: Path, cdir: Path, k: int) -> None:
    """Move pending chunk ``k`` into ``cdir`` (the driver, in index order)."""
    os.replace(chunk_path(pending, k), chunk_path(cdir, k))


def discard_pending(pending: Path) -> int:
    """Remove the pending folder; the number of finished chunks it held (extra chunks)."""
    if not pending.is_dir():
        return 0
    n = sum(1 for p in pending.iterdir() if CHUNK_RE.match(p.name))
    shutil.rmtree(pending, ignore_errors=True)
    return n


def drop_chunks(cdir: Path, indices: Sequence[int]) -> None:
    """Remove finished chunks ``indices`` (the last ones), the highest first: a kill on the way
    leaves the chunks before it whole, with no gap."""
    for k in sorted(indices, reverse=True):
        shutil.rmtree(chunk_path(cdir, k))
