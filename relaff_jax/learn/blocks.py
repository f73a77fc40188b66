"""Step 3 of the protocol, one block: a (target, repetition, chunk of sizes) of the sweep.

Takes a target pool's states ``X: (M, D)``, labels ``y: (M,)``, bootstrap inputs ``boot: (R,
M)``, the target's condition plan and one repetition's draw; ``block_outcomes`` fits one
forest per distinct bootstrap input set and size (``engine.fit_many``), predicts the test set with
all of them at once (``engine.predict_many``) and gives the test accuracies ``(C, sizes)``,
every test scene's outcome ``(C, sizes, T)`` and, at the selection size, each candidate's
leave-one-out accuracy on its own training samples ``(C,)`` (what an agent knows after n
samples: the online "best after ten"). ``run_block`` is its accuracies alone.
``run_block_to_file`` saves a block atomically, with the accuracy on each test subset
(``SUBSETS``: positives, feasible and infeasible negatives); ``read_block`` reads a finished block back
(None if missing or corrupt, so a killed sweep resumes with the finished blocks).
The sweep sends each block to a worker as ``run_block_job(Target, BlockJob)``: the target's
pool, shared by all its blocks (sent to a cluster once), and the block's own named inputs.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np

from relaff_jax import io as rio
from relaff_jax.learn.forest.engine import predict_many
from relaff_jax.learn.learners import fit_many
from relaff_jax.config.experiment import ForestConfig
from relaff_jax.learn.states import augment
from relaff_jax.provenance import derive_seeds

FLUSH = 256  # fast / compiled forests fitted and evaluated together (bounds the trees held in memory)
# test subsets an accuracy is broken down by: what a negative label is made of (issue 24)
SUBSETS = ("positives", "feasible negatives", "infeasible negatives")


def block_outcomes(X: np.ndarray, y: np.ndarray, boot: np.ndarray, plan: Sequence[tuple[int, tuple[int, ...]]],
                   train_order: np.ndarray, test_idx: np.ndarray, sizes: Sequence[int], repeats: int | Mapping[int, int],
                   n_conditions: int, forest: ForestConfig, seed_keys: Sequence[int],
                   loo_size: int | None = None, loo_conditions: Sequence[int] = (),
                   only: frozenset[int] | None = None) -> dict[str, np.ndarray]:
    """Outcomes of one (target, repetition) over a chunk of sizes.

    X: (M, D) target-pool states in the target's order; y: (M,) labels; boot: (R, M) 0/1
    bootstrap inputs on the same scenes; plan: ``[(condition, rows of boot)]``; train_order:
    (>= max(sizes),) training sample order (size n uses its first n); test_idx: (T,);
    repeats: how often each bootstrap input is repeated (``states.augment``), one number or
    per condition of the plan (``condition_repeats``: DBn's may differ; a user's condition: 1).
    Returns ``acc: (C, S)`` test accuracy, ``correct: (C, S, T)`` bool per test scene and
    ``loo: (C,)`` leave-one-out accuracy at ``loo_size`` of the ``loo_conditions`` (NaN
    elsewhere, or everywhere when ``loo_size`` is not in ``sizes``). Conditions not in the
    plan stay NaN (``correct`` False). Conditions with the same rows and repeats share one learner.
    Forest seeds come from ``seed_keys`` + (n, first condition with these rows) and, for the
    leave-one-out forests, + (held-out position + 1). ``only``: fit just the learners of these
    conditions (the others stay NaN; ``reuse.refit``), with the seeds they have in the whole plan.
    """
    acc = np.full((n_conditions, len(sizes)), np.nan)
    correct = np.zeros((n_conditions, len(sizes), len(test_idx)), bool)
    loo = np.full(n_conditions, np.nan)
    first: dict[tuple, int] = {}  # (rows, repeats) -> the first condition with them
    y = np.asarray(y).astype(bool)
    X = np.asarray(X, dtype=np.float32)
    d0 = X.shape[1]
    boot = np.asarray(boot, dtype=np.float32)
    y_test = y[test_idx]
    # the test rows' columns, shared by every forest of the block: the state, then every
    # bootstrap input row once; forest features map to them (augment repeats input columns)
    ZT = np.concatenate([X[test_idx].T, boot[:, test_idx]])
    fits, colmaps, slots = [], [], []  # forests to fit: (X, y, seed), evaluated at each flush
    loo_n = int(loo_size) if loo_size is not None and loo_size in sizes else None
    if loo_n is not None:
        tr_loo = np.asarray(train_order[:loo_n])
        ZL = np.concatenate([X[tr_loo].T, boot[:, tr_loo]])  # the n training scenes' columns
    loo_fits, loo_maps, loo_slots = [], [], []

    def fit_all(batch):
        return fit_many([b[0] for b in batch], [b[1] for b in batch], [b[2] for b in batch], forest)

    def flush():  # fit and predict the pending forests at once (the sklearn engine one by one)
        for (c, si), p in zip(slots, predict_many(fit_all(fits), ZT, colmaps)):
            correct[c, si] = p.astype(bool) == y_test
            acc[c, si] = np.mean(correct[c, si])
        fits.clear(), colmaps.clear(), slots.clear()

    def flush_loo():  # each leave-one-out forest predicts its held-out training scene
        if loo_fits:
            p = predict_many(fit_all(loo_fits), ZL, loo_maps)
            for k, (c, i) in enumerate(loo_slots):
                loo_hits[c].append(bool(p[k, i]) == bool(y[tr_loo[i]]))
        loo_fits.clear(), loo_maps.clear(), loo_slots.clear()

    loo_hits: dict[int, list[bool]] = {}
    batch = 1 if forest.engine == "sklearn" else FLUSH
    # every forest's seed at once (one SeedSequence per seed would cost ~20 us a forest)
    firsts: dict[tuple, int] = {}
    for c, r in plan:
        firsts.setdefault(learner_key(r, repeats, c), c)
    learners = list(firsts.values())  # the first condition of each learner, in plan order
    row = {c: i for i, c in enumerate(learners)}
    seeds = derive_seeds([(*seed_keys, n, c) for c in learners for n in sizes]).reshape(len(learners), len(sizes))
    if loo_n is not None:
        loo_seeds = derive_seeds([(*seed_keys, loo_n, c, i + 1) for c in learners for i in range(loo_n)])
        loo_seeds = loo_seeds.reshape(len(learners), loo_n)
    for cond, rows in plan:
        key = learner_key(rows, repeats, cond)
        if key in first:
            continue
        first[key] = cond
        if only is not None and not any(c in only for c, r in plan if learner_key(r, repeats, c) == key):
            continue  # another reading's block gives this learner's outcomes
        rep = key[1]
        inputs = boot[list(rows)]
        if not np.all(np.isfinite(inputs)):
            raise ValueError(f"condition {cond}: bootstrap inputs {rows} were not computed for this space")
        colmap = np.concatenate([np.arange(d0), d0 + np.repeat(np.asarray(rows, dtype=np.intp), rep)])
        # nested training sets: size n's states are the first n rows of the largest size's
        tr = train_order[:max(sizes)]
        XA, yA = augment(X[tr], inputs[:, tr], rep), y[tr]
        for si, n in enumerate(sizes):
            fits.append((XA[:n], yA[:n], int(seeds[row[cond], si])))
            colmaps.append(colmap)
            slots.append((cond, si))
            if len(fits) >= batch:
                flush()
        if loo_n is not None and any(c in loo_conditions for c, r in plan if learner_key(r, repeats, c) == key):
            loo_hits[cond] = []
            for i in range(loo_n):
                keep = np.delete(tr_loo, i)
                loo_fits.append((augment(X[keep], inputs[:, keep], rep), y[keep], int(loo_seeds[row[cond], i])))
                loo_maps.append(colmap)
                loo_slots.append((cond, i))
                if len(loo_fits) >= batch:
                    flush_loo()
    flush()
    flush_loo()
    for c, hits in loo_hits.items():
        loo[c] = np.mean(hits)
    for cond, rows in plan:
        f = first[learner_key(rows, repeats, cond)]
        if f != cond:
            acc[cond], correct[cond], loo[cond] = acc[f], correct[f], loo[f]
    return {"acc": acc, "correct": correct, "loo": loo}


def learner_key(rows: tuple[int, ...], repeats: int | Mapping[int, int], cond: int) -> tuple[tuple[int, ...], int]:
    """What makes a condition's learner: its bootstrap rows and how often each is repeated
    (none without rows: NB's learner whatever the number)."""
    rep = int(repeats if isinstance(repeats, (int, np.integer)) else repeats[cond])
    return tuple(rows), (rep if rows else 0)


def run_block(X: np.ndarray, y: np.ndarray, boot: np.ndarray, plan: Sequence[tuple[int, tuple[int, ...]]],
              train_order: np.ndarray, test_idx: np.ndarray, sizes: Sequence[int], repeats: int | Mapping[int, int],
              n_conditions: int, forest: ForestConfig, seed_keys: Sequence[int]) -> np.ndarray:
    """Accuracies ``(C, len(sizes))`` of one (target, repetition) over a chunk of sizes
    (``block_outcomes``' ``acc``)."""
    return block_outcomes(X, y, boot, plan, train_order, test_idx, sizes, repeats, n_conditions, forest, seed_keys)["acc"]


def subset_accuracy(correct: np.ndarray, subset: np.ndarray) -> np.ndarray:
    """``(..., N_SUBSETS)`` accuracy on each test subset of ``correct: (..., T)`` bool outcomes;
    ``subset: (T,)`` int codes into ``SUBSETS`` (-1: unknown, counted in none); NaN where a
    subset has no test scene or the condition did not run (all-False outcomes of a NaN
    accuracy are not a measurement)."""
    correct = np.asarray(correct, bool)
    subset = np.asarray(subset)
    out = np.full(correct.shape[:-1] + (len(SUBSETS),), np.nan)
    for k in range(len(SUBSETS)):
        m = subset == k
        if m.any():
            out[..., k] = correct[..., m].mean(-1)
    return out


def run_block_to_file(path: str, X, y, boot, plan, train_order, test_idx, sizes, repeats, n_conditions, forest, seed_keys,
                      loo_size=None, loo_conditions=(), keep_outcomes=True, subset=None, only=None, donor=None):
    """``block_outcomes``, saved atomically to ``path`` (a finished block; the per scene
    outcomes bit-packed, or left out (``correct: (C, S, 0)``) without ``keep_outcomes``), with
    ``acc_subset: (C, S, N_SUBSETS)``, the accuracy on each test subset (``subset: (T,)``
    codes of the test scenes; None: all unknown), kept even when the outcomes are not.

    Returns the block as saved (what ``read_block(..., packed=True)`` gives back): ``acc``,
    ``loo``, ``acc_subset``, ``bits: (C, S, ceil(T / 8))`` uint8 the outcomes bit-packed along
    the scenes (``np.packbits``) and ``n_test`` T (0 without ``keep_outcomes``): an eighth of
    the unpacked outcomes to send back from a worker process and to hold in the sweep.

    ``only`` and ``donor`` (``learn.reuse``): fit only the conditions in ``only`` and take every
    other condition's outcomes from the block file ``donor`` (another reading's, same sizes)."""
    out = block_outcomes(X, y, boot, plan, train_order, test_idx, sizes, repeats, n_conditions, forest, seed_keys,
                         loo_size, loo_conditions, only)
    if donor is not None:
        got = read_block(Path(donor), n_conditions, sizes)
        if got is None or got["correct"].shape[-1] != len(test_idx):
            raise RuntimeError(f"{donor}: the block to reuse is gone or unreadable; rerun without --reuse")
        keep = [c for c in range(n_conditions) if c not in set(only or ())]
        for k in ("acc", "correct", "loo"):
            out[k][keep] = got[k][keep]
    sub = np.full(len(test_idx), -1) if subset is None else np.asarray(subset)
    acc_subset = np.where(np.isfinite(out["acc"])[..., None], subset_accuracy(out["correct"], sub), np.nan)
    correct = out["correct"] if keep_outcomes else out["correct"][..., :0]
    block = {"acc": out["acc"], "loo": out["loo"], "acc_subset": acc_subset, "bits": np.packbits(correct, axis=-1),
             "n_test": int(correct.shape[-1])}
    rio.atomic_save_npz(path, acc=block["acc"], loo=block["loo"], sizes=np.asarray(sizes), acc_subset=acc_subset,
                        correct=block["bits"], n_test=np.asarray(block["n_test"]))
    return block


class Target(NamedTuple):
    """A target's pool, the same for every block of the target (one object: a cluster gets it once)."""

    X: np.ndarray  # (M, D) the pool scenes' states in the space swept (manipulated object first)
    y: np.ndarray  # (M,) bool labels
    boot: np.ndarray  # (R, M) bootstrap inputs: the prep's source predictors and categories on the pool


@dataclasses.dataclass(frozen=True)
class BlockJob:
    """One block of the sweep: a (target, repetition, chunk of sizes), what ``run_block_to_file``
    takes besides the target's pool (``Target``)."""

    path: str  # the block's file (``learn.folder.block``)
    plan: Sequence[tuple[int, tuple[int, ...]]]  # [(condition, rows of boot)] (``protocol.condition_plan``)
    train_order: np.ndarray  # (>= max(sizes),) int pool indices: size n trains on the first n
    test_idx: np.ndarray  # (T,) int pool indices of the test set
    sizes: Sequence[int]  # (S,) training sizes of this chunk
    repeats: int | Mapping[int, int]  # how often each bootstrap input is repeated, per condition
    n_conditions: int  # C, the condition axis (built-ins, then the user's)
    learner: Any  # ``learners.learner_of(cfg)``: a ``ForestConfig`` or a ``SklearnLearner``
    seed_keys: tuple[int, ...]  # (seed, 5, space code, target, repetition): forest seeds derive from them
    loo_size: int | None  # the online selection size, when this chunk holds it
    loo_conditions: Sequence[int]  # the candidates given a leave-one-out accuracy (every DB1, CB1)
    keep_outcomes: bool  # keep every test scene's outcome (bit-packed)
    subset: np.ndarray  # (T,) int codes into ``SUBSETS`` of the test scenes
    only: frozenset[int] | None = None  # fit only these conditions (``learn.reuse``) ...
    donor: str | None = None  # ... and read the others from this block file


def run_block_job(target: Target, job: BlockJob) -> dict[str, np.ndarray]:
    """``run_block_to_file`` of one block: what the sweep runs on a worker."""
    return run_block_to_file(job.path, target.X, target.y, target.boot, job.plan, job.train_order, job.test_idx,
                             job.sizes, job.repeats, job.n_conditions, job.learner, job.seed_keys, job.loo_size,
                             job.loo_conditions, job.keep_outcomes, job.subset, job.only, job.donor)


def read_block(path: Path, n_conditions: int, sizes: Sequence[int], packed: bool = False) -> dict[str, np.ndarray] | None:
    """A finished block (``acc``, ``correct``, ``loo`` as ``block_outcomes`` gives them, and
    ``acc_subset``), or None if missing or unreadable (then it is recomputed). ``packed``:
    the outcomes as saved, ``bits`` and ``n_test`` instead of ``correct`` (what
    ``run_block_to_file`` returns)."""
    if not path.exists():
        return None
    try:
        with np.load(path) as z:
            acc, s, loo, acc_subset = z["acc"], z["sizes"], z["loo"], z["acc_subset"]
            bits, n_test = z["correct"], int(z["n_test"])
            if bits.dtype != np.uint8 or bits.ndim != 3 or bits.shape[-1] != (n_test + 7) // 8:
                return None
            correct = None if packed else np.unpackbits(bits, axis=-1, count=n_test).astype(bool)
    except Exception:  # a corrupt file (or one of an older format) cannot be a finished block
        return None
    if acc.shape != (n_conditions, len(sizes)) or list(s) != list(sizes) or bits.shape[:2] != acc.shape:
        return None
    if packed:
        return {"acc": acc, "loo": loo, "acc_subset": acc_subset, "bits": bits, "n_test": n_test}
    return {"acc": acc, "correct": correct, "loo": loo, "acc_subset": acc_subset}
