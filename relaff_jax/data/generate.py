"""Generation of a balanced, resumable dataset of labelled rollouts for one action.

Takes a *rollout function* ``rollout_fn(key, batch_size) -> dict[str, array]`` that simulates
and labels one batch of scenes, an action, a seed and the dataset node (``DatasetConfig``: N is
its ``n_samples``, the batch size its ``rollout_batch``, with the selection's settings); gives a dataset
directory holding every rollout (orbax chunks) and a balanced selection of N of them
(``selection.py``), and returns a summary.

Every rollout dict holds, with leading axis ``B`` (the batch size): ``label`` (B,) bool,
``relation`` (B,) str in ``RELATIONS`` (or int codes into ``RELATIONS``), ``cog_distance``
(B,) float metres, ``toy`` and ``other`` (B,) object names (or int ids into
``object_names``), plus any other numeric or string per-sample arrays (poses, pair index,
per-sample seed, ...). Strings are stored as int32 codes with a per-chunk vocabulary (orbax's
tensorstore backend has no string dtype) and come back as numpy ``str`` arrays. The driver
adds ``rollout`` (B,) int64, the global rollout index ``chunk * batch + i``.

Determinism: chunk ``k`` is simulated with ``jax.random.fold_in(PRNGKey(seed), k)``, the
generator stops after the first chunk count at which a balanced selection exists, and the
selection is a function of the stored labels/distances and ``seed`` only; so a run that is
killed and rerun gives the same chunks and the same dataset as one that never stopped.
Layout, selection scheme and error cases: ``docs/datasets.md``.

With a Dask ``client`` (docs/cluster.md) chunks are tasks (``tasks.rollout_chunk``), one per
worker thread in flight, written to ``chunks/.pending`` and moved into place by this driver
in index order, so the stopping point and the selection are those of the run without a
cluster; chunks simulated past the stopping point are waited for and discarded (counted in
the summary's ``discarded_chunks``). ``rollout_fn`` must then be picklable, best a
``relaff_jax.cluster.Remote`` (built once per worker). Without a client, a rollout function
with two halves (``prepare``/``execute``, ``sim.rollouts.RolloutFn``) has chunk ``k + 1``'s
first half run on a background thread while chunk ``k`` executes (``tasks.PrepareAhead``;
the same calls on the same keys, so the same chunks).
"""
from __future__ import annotations

import math
import os
import sys
import warnings
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax import provenance
from relaff_jax.cluster.tasks import Ordered
from relaff_jax.config import to_dict
from relaff_jax.data.features import remove_features
from relaff_jax.data.layout import (CHUNKS, FEATURES, FEATURES_SIDECAR, FORMAT, FORMAT_VERSION, SELECTION, SIDECAR, check_action, check_int, jsonable_config, scheme_changes, selection_scheme, stored_scheme)
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.data.errors import CorruptDatasetError, DatasetError, DatasetMismatchError, RolloutCapError
from relaff_jax.data.load import load_dataset
from relaff_jax.data.progress import progress_bar
from relaff_jax.data.selection import select_balanced
from relaff_jax.data.stopping import eligible_rows, first_stop, stops
from relaff_jax.data.store import (check_rollout_ids, chunk_dirs_exist, chunk_indices, chunk_path, clean_tmp,
                                   mismatch, prepare_dir, read_chunk, read_sidecar, remove_created, sha256,
                                   writer_lock)
from relaff_jax.data.tasks import PENDING, PrepareAhead, discard_pending, drop_chunks, promote, rollout_chunk
from relaff_jax.data.validate import check_schema, schema_of

# The settle each engine's rollout_fn uses, recorded in the sidecar and compared on resume
# (the native name is ``relaff_jax.sim.native.settle.SETTLE_NAME``; tests check they match).
SETTLE_OF_ENGINE = {"mjx": "mjx", "native": "mujoco_c_batch/1"}


def generate_dataset(
    out_dir: str | os.PathLike,
    action: str,
    rollout_fn: Callable[[Any, int], Mapping[str, Any]],
    seed: int,
    config_dict: Mapping[str, Any] | None = None,
    progress: bool = True,
    *,
    dataset_config: DatasetConfig | None = None,
    object_names: Sequence[str] | None = None,
    client: Any = None,
    window: int | None = None,
) -> dict[str, Any]:
    """Simulate rollouts in chunks until ``dataset_config.n_samples`` balanced samples exist;
    write the dataset.

    out_dir: new, empty or resumable dataset directory.
    rollout_fn(key, batch) -> dict of (batch, ...) arrays (see module docstring); called with
        ``jax.random.fold_in(jax.random.PRNGKey(seed), k)`` for chunk ``k``, always with
        ``batch = dataset_config.rollout_batch`` as its second argument (static shapes: one compile).
    config_dict: the action/physics config, stored in the sidecar and compared on resume.
    dataset_config: the dataset node (default ``DatasetConfig()``), the one source of the sizes
        (``n_samples``, ``rollout_batch``) and of the selection's settings; recorded in the sidecar.
    object_names: table for int ``toy``/``other`` ids, if the rollout_fn returns ids.
    client: a ``distributed.Client`` to simulate chunks on (None: in this process); ``window``:
        chunks in flight at once (default: the cluster's task slots).
    Returns a summary: ``rollouts`` simulated, ``chunks``, ``positives``/``positive_rate``
    over all rollouts, ``borrowed`` negatives, ``new_chunks`` simulated by this call,
    ``discarded_chunks`` simulated past the stopping point (with a cluster) and dropped.
    """
    check_action(action)
    dcfg = dataset_config or DatasetConfig()
    n_samples = int(dcfg.n_samples)  # the node checked both when it was built; int: JSON of a numpy int
    batch = int(dcfg.rollout_batch)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    if not callable(rollout_fn):
        raise DatasetError("rollout_fn must be callable")
    config = jsonable_config(config_dict)
    header = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "action": action,
        "n_samples": n_samples,
        "seed": seed,
        "batch": batch,
        "config": config,
        "object_names": list(object_names) if object_names is not None else None,
        "selection_scheme": selection_scheme(dcfg),
        "engine": dcfg.engine,  # the caller's rollout_fn must use it (cli and reproduce build both from one config)
        "settle": SETTLE_OF_ENGINE[dcfg.engine],
    }
    path = Path(out_dir)
    created = prepare_dir(path)
    # Losing the lock race leaves the folder to the winner, even if this call created it.
    with writer_lock(path):
        try:
            return _generate_locked(path, header, rollout_fn, dcfg, object_names, progress, client, window)
        except BaseException:
            # A dataset this call created but never gave a chunk leaves nothing behind.
            if created and not chunk_dirs_exist(path):
                discard_pending(path / CHUNKS / PENDING)
                remove_created(path)
            raise


def _check_objects(path: Path, meta: Mapping[str, Any], header: Mapping[str, Any]) -> None:
    """Refuse to resume with other objects (``config.objects``: ``sim.object_library.record``,
    absent for the built-ins): its sha256 covers every selected object's specs."""
    rec = lambda m: (m.get("config") or {}).get("objects") or {} if isinstance(m.get("config"), dict) else {}
    old, new = rec(meta), rec(header)
    if old.get("sha256") != new.get("sha256"):
        name = lambda r: (f"objects {r['sha256'][:12]} (library {r.get('library') or 'none'})" if r
                          else "the 29 built-in objects")
        raise DatasetMismatchError(
            f"{path}: was generated with {name(old)}, this run resolves to {name(new)}; resuming would mix two "
            f"object sets in one dataset. Restore the library file (or selection) it was made with, or write to a "
            f"new folder")


def _generate_locked(path, header, rollout_fn, dcfg, object_names, progress, client, window) -> dict[str, Any]:
    cdir = path / CHUNKS
    clean_tmp(path, cdir)
    if (path / SIDECAR).exists():
        meta = read_sidecar(path)
        meta["selection_scheme"] = stored_scheme(meta.get("selection_scheme", {}))
        if meta["engine"] != header["engine"]:
            raise DatasetMismatchError(
                f"{path}: was generated with the {meta['engine']} engine; resuming it with the {header['engine']} "
                f"engine would mix two simulators in one dataset. Rerun with --engine {meta['engine']} "
                f"(--set dataset.engine={meta['engine']}) or write to a new folder")
        settled = meta.get("settle", "mjx")  # a sidecar without it predates the C settle: MJX settled it
        if settled != header["settle"]:
            raise DatasetMismatchError(
                f"{path}: its scenes were settled by {settled}, this version's {header['engine']} engine settles "
                f"them by {header['settle']}; resuming would mix two settles in one dataset. Write to a new "
                f"folder (or finish it with the version that began it)")
        meta["settle"] = settled
        _check_objects(path, meta, header)
        diff = mismatch(meta, header, ("action", "n_samples", "seed", "batch", "config", "object_names"))
        if diff:
            raise DatasetMismatchError(f"{path}: holds a different dataset; " + "; ".join(diff))
        # the same rollouts under another selection scheme: selected again from the stored chunks
        changed = scheme_changes(meta["selection_scheme"], header["selection_scheme"])
        reselect = bool(changed)
        if reselect:
            print(f"{path}: selecting again from the stored rollouts ({', '.join(changed)})", file=sys.stderr)
        elif meta["status"] == "complete":
            load_dataset(path)  # verifies chunks and index
            return _summary(meta, new_chunks=0)
    else:
        reselect = False
        meta = dict(header, status="generating", counts={"chunks": 0, "rollouts": 0, "positives": 0})
        meta["versions"] = provenance.versions()
        meta["dataset_config"] = to_dict(dcfg)
        rio.atomic_write_json(path / SIDECAR, meta)
    meta["dataset_config"] = to_dict(dcfg)  # the cap may change between runs; record the last
    action, n, seed, batch = meta["action"], meta["n_samples"], meta["seed"], meta["batch"]

    done = chunk_indices(cdir)
    if len(done) < meta["counts"]["chunks"]:
        raise CorruptDatasetError(
            f"{path}: sidecar records {meta['counts']['chunks']} chunks but only {len(done)} exist (truncated)"
        )
    labels, dists, eligible, refused, schema = [], [], [], [], None
    for k in done:
        arrays, _ = read_chunk(chunk_path(cdir, k))
        check_rollout_ids(chunk_path(cdir, k), arrays, k, batch)
        arrays.pop("rollout")
        check_schema(f"chunk {k}", schema_of(arrays), schema)
        schema = schema or schema_of(arrays)
        labels.append(arrays["label"])
        dists.append(arrays["cog_distance"])
        ok_k, refused_k = eligible_rows(arrays, dcfg, f"chunk {k}")
        eligible.append(ok_k)
        refused.append(refused_k)
    max_chunks = math.ceil(dcfg.max_rollouts / batch)
    if reselect:  # stop where a run under this scheme from the start would have: the same dataset
        k_stop = first_stop(labels, dists, eligible, n, seed, dcfg, max_chunks)
        if k_stop is not None and k_stop < len(done):
            # counts first, the old scheme kept: a kill while removing leaves a rerun that selects again
            done, labels, dists, eligible, refused = (x[:k_stop] for x in (done, labels, dists, eligible, refused))
            meta["counts"].update(chunks=k_stop, rollouts=k_stop * batch, positives=int(sum(l.sum() for l in labels)))
            meta["status"] = "generating"  # the old selection no longer matches the chunks
            rio.atomic_write_json(path / SIDECAR, meta)
            extra = chunk_indices(cdir)[k_stop:]
            drop_chunks(cdir, extra)
            print(f"{path}: {len(extra)} chunks past this scheme's stopping point removed", file=sys.stderr)
        if (path / FEATURES_SIDECAR).exists() or (path / FEATURES).exists():  # they belong to the old selection
            remove_features(path)
            print(f"{path}: the old selection's features removed", file=sys.stderr)
        meta["selection_scheme"], meta["status"] = header["selection_scheme"], "generating"
        rio.atomic_write_json(path / SIDECAR, meta)
    k0 = len(done)
    # the bar counts samples of a balanced selection in hand, negatives matched included, so
    # it does not stand at 100 % while negatives are still being matched
    bar = progress_bar(progress, n, f"{action} samples" if done else f"{action}: compiling, first chunk", unit="sample")
    k = k0
    pending = cdir / PENDING
    clean_tmp(pending)
    # without a cluster chunks are written in place, as always (unless a cluster run left some pending)
    stage = pending if client is not None or pending.is_dir() else cdir
    # without a cluster the next chunk is prepared while this one executes (tasks.PrepareAhead)
    ahead = PrepareAhead(rollout_fn, seed, batch, max_chunks) if client is None and PrepareAhead.supports(rollout_fn) else None
    runner = Ordered(client, lambda j: (rollout_chunk, (rollout_fn, seed, j, batch, object_names, str(stage), schema, ahead)),
                     max_chunks, window)
    try:
        while True:
            lab = np.concatenate(labels) if labels else np.zeros(0, bool)
            dist = np.concatenate(dists) if dists else np.zeros(0)
            ok = np.concatenate(eligible) if eligible else np.zeros(0, bool)
            sel = select_balanced(lab, dist, n, seed, dcfg.distance_bins, eligible=ok, negatives=dcfg.negatives)
            in_hand = samples_in_hand(sel, lab, ok, n, dcfg.borrow_fraction)
            bar.update(in_hand - bar.n)
            if meta["counts"].get("in_hand") != in_hand:  # read by reproduce's progress line
                meta["counts"]["in_hand"] = in_hand
                rio.atomic_write_json(path / SIDECAR, meta)
            at_cap = k >= max_chunks
            if stops(sel, k, labels, eligible, n, dcfg, max_chunks):
                break
            if at_cap:
                rate = lab.mean() if lab.size else float("nan")
                which = "" if dcfg.population == "all" else f" (population {dcfg.population!r}: {int(ok.sum())} eligible)"
                raise RolloutCapError(
                    f"{action}: rollout cap reached (max_rollouts={dcfg.max_rollouts}, {lab.size} rollouts in "
                    f"{k} chunks{which}) with {int((lab & ok).sum())} positives and {int((~lab & ok).sum())} negatives, "
                    f"positive rate {rate:.2%}; {n} samples need {n // 2} positives and {n - n // 2} "
                    f"negatives. Rerun with a larger max_rollouts to continue from the chunks kept in {cdir}."
                )
            got = runner.get(k)
            if k == k0 and not done:
                bar.set_description(f"{action} samples")
            check_schema(f"chunk {k} from rollout_fn", got["schema"], schema)
            schema = schema or got["schema"]
            if stage != cdir:
                promote(stage, cdir, k)
            labels.append(got["label"])
            dists.append(got["cog_distance"])
            ok_k, refused_k = eligible_rows(got, dcfg, f"chunk {k} from rollout_fn")
            eligible.append(ok_k)
            refused.append(refused_k)
            k += 1
            npos = int(sum(l.sum() for l in labels))
            meta["counts"].update(chunks=k, rollouts=k * batch, positives=npos)
            rio.atomic_write_json(path / SIDECAR, meta)
            bar.set_postfix(rollouts=k * batch, pos_rate=f"{npos / (k * batch):.1%}")
    except BaseException:
        runner.cancel()  # tasks already running still finish into chunks/.pending, kept for a rerun
        raise
    finally:
        bar.close()
        if ahead is not None:
            ahead.close()
    runner.finish()  # chunks past the stopping point: wait until written, then drop them
    discarded = discard_pending(pending)
    met = sel.borrowed <= dcfg.borrow_fraction * sel.n_negative
    if not met:
        why = "rollout cap reached" if k >= max_chunks else f"match_patience {dcfg.match_patience} reached at {k} chunks"
        warnings.warn(
            f"{action}: the distance matching was not met ({why}); {sel.borrowed} of {sel.n_negative} "
            f"negatives come from outside their COG-distance bin ({sel.borrowed / sel.n_negative:.1%}; "
            f"recorded in {SELECTION}; population {dcfg.population!r}, negatives {dcfg.negatives!r})",
            stacklevel=2,
        )
    index = {
        "n": n,
        "n_positive": sel.n_positive,
        "n_negative": sel.n_negative,
        "seed": seed,
        "chunks": k,
        "rollouts": k * batch,
        "bin_edges": sel.bin_edges.tolist(),
        "positive_bin_counts": sel.positive_bin_counts.tolist(),
        "negative_bin_counts": sel.negative_bin_counts.tolist(),
        "borrowed": sel.borrowed,
        "borrowed_share": sel.borrowed / sel.n_negative,
        "matching_met": bool(met),
        "population": dcfg.population,
        "negatives": dcfg.negatives,
        "eligible_rollouts": int(ok.sum()),
        "unsettled": dcfg.unsettled,
        "unsettled_refused": None if None in refused else int(sum(refused)),
        "at_cap": bool(k >= max_chunks),
        "selected": sel.selected.tolist(),
    }
    rio.atomic_write_json(path / SELECTION, index)
    meta["status"] = "complete"
    meta["selection"] = {key: index[key] for key in ("n", "n_positive", "n_negative", "chunks", "rollouts", "borrowed",
                                                     "borrowed_share", "matching_met", "population", "negatives",
                                                     "eligible_rollouts", "unsettled", "unsettled_refused", "at_cap")}
    meta["selection"]["sha256"] = sha256(sel.selected.astype(np.int64))
    rio.atomic_write_json(path / SIDECAR, meta)
    summary = dict(_summary(meta, new_chunks=k - k0), discarded_chunks=discarded)
    if progress:
        extra = f"; {discarded} chunks simulated past the stopping point discarded" if discarded else ""
        print(
            f"{action}: {n} samples selected from {summary['rollouts']} rollouts ({k} chunks, "
            f"{k - k0} new), positive rate {summary['positive_rate']:.2%}, "
            f"{sel.borrowed} negatives borrowed across distance bins{extra}",
            file=sys.stderr,
        )
    return summary


def samples_in_hand(sel, label: np.ndarray, eligible: np.ndarray, n: int, borrow_fraction: float) -> int:
    """How many of the ``n`` samples a balanced selection has now: positives plus negatives
    within their distance bin (a negative borrowed beyond ``borrow_fraction`` is still owed).

    sel: ``select_balanced``'s result or None (no balanced selection yet); label, eligible:
    (R,) bool over every rollout so far."""
    if sel is None:
        pos = int((label & eligible).sum())
        neg = int((~label & eligible).sum())
        return min(pos, n // 2) + min(neg, n - n // 2)
    owed = max(0, sel.borrowed - math.floor(borrow_fraction * sel.n_negative))
    return n - owed


def _summary(meta: Mapping[str, Any], new_chunks: int) -> dict[str, Any]:
    c = meta["counts"]
    return {
        "action": meta["action"],
        "n": meta["n_samples"],
        "rollouts": c["rollouts"],
        "chunks": c["chunks"],
        "positives": c["positives"],
        "positive_rate": c["positives"] / c["rollouts"] if c["rollouts"] else float("nan"),
        "borrowed": meta.get("selection", {}).get("borrowed"),
        "matching_met": meta.get("selection", {}).get("matching_met"),
        "new_chunks": new_chunks,
        "discarded_chunks": 0,
    }
