"""Dataset storage layer: balance, COG-distance matching, determinism, resume, errors, info, features.

The rollout function is a synthetic test fixture (tests/helpers/standins.py) (numpy draws seeded by the chunk key),
not physics: "beside" scenes are far apart and rarely positive, "on_top"/"inside" scenes are
close and mostly positive, which is the regime the paper's distance matching is about.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from relaff_jax import data as ds
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.cli import data as cli_data
from relaff_jax.data import generate, store
from relaff_jax.config.constraints import ConfigError
from relaff_jax.errors import UserError

from helpers import ROOT, TESTS
from helpers.standins import ACTION_CFG as CFG
from helpers.standins import DATASET_OTHERS as OTHERS
from helpers.standins import DATASET_TOYS as TOYS
from helpers.standins import EXACT, Killed, feature_fn, gen, synthetic_rollout_fn

EXACT40 = dataclasses.replace(EXACT, n_samples=40, rollout_batch=16)  # what gen() builds by default


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    path = tmp_path_factory.mktemp("ds") / "lift"
    summary = gen(path)
    return path, summary


def copy(built, tmp_path) -> Path:
    dst = tmp_path / "copy"
    shutil.copytree(built[0], dst)
    return dst


# ----------------------------------------------------------------------------- selection


def test_select_balanced_hand_worked():
    # positives at 1.0 and 2.0, 2 bins [1, 1.5) [1.5, 2]; one negative per bin, one far away
    label = np.array([1, 1, 0, 0, 0], bool)
    dist = np.array([1.0, 2.0, 1.1, 1.9, 5.0])
    sel = ds.select_balanced(label, dist, 4, seed=0, bins=2)
    assert sel.selected.tolist() == [0, 1, 2, 3]
    assert sel.bin_edges.tolist() == [1.0, 1.5, 2.0]
    assert sel.borrowed == 0
    # bin 0 has no negative: its quota is filled by the nearest leftover (1.6 or 1.9, both
    # nearer to [1, 1.5] than 0.5 is), the other one fills bin 1
    label = np.array([1, 1, 0, 0, 0, 0], bool)
    dist = np.array([1.0, 2.0, 1.6, 1.9, 0.5, 3.0])
    for seed in range(5):
        sel = ds.select_balanced(label, dist, 4, seed=seed, bins=2)
        assert sel.selected.tolist() == [0, 1, 2, 3]
        assert sel.borrowed == 1
        assert sel.negative_bin_counts.tolist() == [0, 1]
    # odd N: one more negative than positive; too few of a class: None
    sel = ds.select_balanced(np.array([1, 1, 0, 0, 0]), np.arange(5.0), 5, seed=0, bins=2)
    assert (sel.n_positive, sel.n_negative, len(sel.selected)) == (2, 3, 5)
    assert ds.select_balanced(np.array([1, 0, 0]), np.arange(3.0), 4, seed=0) is None


def test_balance_and_distance_histogram(built):
    path, summary = built
    d = ds.load_dataset(path)
    assert d["label"].shape == (40,)
    assert d["label"].dtype == bool
    assert d["label"].sum() == 20  # exactly 50 %
    # independent check: 8 equal-width bins over the positives' distance range (np.histogram)
    pos, neg = d["cog_distance"][d["label"]], d["cog_distance"][~d["label"]]
    edges = np.linspace(pos.min(), pos.max(), 9)
    hp, _ = np.histogram(pos, edges)
    hn, _ = np.histogram(neg, edges)
    assert hp.tolist() == hn.tolist()
    assert hn.sum() == 20
    # ... whereas the unselected negatives are distributed differently (far "beside" scenes)
    r = ds.load_rollouts(path)
    all_neg = r["cog_distance"][~r["label"]]
    assert np.histogram(all_neg, edges)[0].sum() < len(all_neg)
    assert summary["rollouts"] == len(r["label"]) == summary["chunks"] * 16
    assert summary["borrowed"] == 0


def test_loaded_fields(built):
    path, _ = built
    d = ds.load_dataset(path)
    r = ds.load_rollouts(path)
    assert d["action"] == "lift"
    assert r["action"] == "lift"
    assert set(d["relation"]) <= set(ds.RELATIONS)
    assert d["relation"].dtype.kind == "U"
    assert set(d["toy"]) <= set(TOYS)
    assert set(d["other"]) <= set(OTHERS)
    assert d["qpos"].shape == (40, 2, 7)
    assert d["qpos"].dtype == np.float32
    assert d["sample_seed"].dtype == np.uint32
    assert d["pair"].dtype == np.int32
    assert r["rollout"].tolist() == list(range(len(r["label"])))
    assert r["selected"].sum() == 40
    for k in ("label", "relation", "cog_distance", "toy", "other", "qpos"):
        np.testing.assert_array_equal(d[k], r[k][r["selected"]])
    # the stored rollouts are exactly what the rollout function returned for each chunk key
    import jax

    for k in range(2):
        want = synthetic_rollout_fn()(jax.random.fold_in(jax.random.PRNGKey(3), k), 16)
        sl = slice(16 * k, 16 * (k + 1))
        for name, a in want.items():
            np.testing.assert_array_equal(r[name][sl], a)


def test_determinism(built, tmp_path):
    path, _ = built
    again = tmp_path / "again"
    gen(again)
    a, b = ds.load_dataset(path), ds.load_dataset(again)
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    other = tmp_path / "other"
    gen(other, seed=4)
    assert not np.array_equal(ds.load_dataset(other)["cog_distance"], a["cog_distance"])


def test_resume_after_kill_is_identical(built, tmp_path):
    path, summary = built
    assert summary["chunks"] > 3
    part = tmp_path / "part"
    with pytest.raises(Killed):
        gen(part, fn=synthetic_rollout_fn(kill_after=2))
    assert sorted(p.name for p in (part / "chunks").iterdir()) == ["chunk_000000", "chunk_000001"]
    with pytest.raises(ds.DatasetError, match="not finished"):
        ds.load_dataset(part)
    # leftovers of a kill inside an atomic write, and a sidecar that lags one chunk behind
    junk = part / "chunks" / ".chunk_000002.abcd.tmp"
    (junk / "arrays").mkdir(parents=True)
    (part / ".relaff_dataset.json.xyz.tmp").write_text("{")
    side = json.loads((part / ds.SIDECAR).read_text())
    side["counts"]["chunks"] = 1
    (part / ds.SIDECAR).write_text(json.dumps(side))
    calls: list = []
    res = gen(part, fn=synthetic_rollout_fn(calls=calls))
    assert res["new_chunks"] == summary["chunks"] - 2 == len(calls)
    assert res["rollouts"] == summary["rollouts"]
    assert not junk.exists()
    assert not (part / ".relaff_dataset.json.xyz.tmp").exists()
    names = sorted(p.name for p in (part / "chunks").iterdir())
    assert names == [f"chunk_{k:06d}" for k in range(summary["chunks"])]
    a, b = ds.load_dataset(path), ds.load_dataset(part)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    ra, rb = ds.load_rollouts(path), ds.load_rollouts(part)
    for k in ra:
        np.testing.assert_array_equal(ra[k], rb[k])
    assert len(np.unique(rb["rollout"])) == len(rb["rollout"])
    # a finished dataset rerun with the same arguments simulates nothing
    again = gen(part, fn=synthetic_rollout_fn(kill_after=0))
    assert again["new_chunks"] == 0
    assert again["rollouts"] == summary["rollouts"]


class TwoHalves:
    """A rollout function with two halves (``prepare``, ``execute``), as ``sim.rollouts.RolloutFn``:
    the synthetic draws, made by ``execute``; records the thread each chunk was prepared on;
    ``execute`` raises ``Killed`` after ``kill_after`` chunks, ``prepare`` at chunk ``fail_at``."""

    def __init__(self, kill_after=None, fail_at=None):
        self.draw, self.kill_after, self.fail_at = synthetic_rollout_fn(), kill_after, fail_at
        self.threads, self.executed = [], 0

    def prepare(self, key, b):
        import threading

        self.threads.append(threading.current_thread().name)
        if self.fail_at is not None and len(self.threads) > self.fail_at:
            raise Killed("simulated failure of a prepared half")
        return key, b

    def execute(self, prepared):
        if self.kill_after is not None and self.executed >= self.kill_after:
            raise Killed("simulated kill")
        self.executed += 1
        return self.draw(*prepared)

    def __call__(self, key, b):
        return self.execute(self.prepare(key, b))


def test_next_chunk_prepared_ahead_gives_the_same_dataset_and_resumes(built, tmp_path):
    """Without a cluster a two-halved rollout function's next chunk is prepared on a background
    thread while this one executes: the same dataset as one call per chunk; a kill in an
    execution or a failure in a prepared half keeps every chunk written before it, and the
    rerun finishes the same dataset; at most one chunk is prepared past the stopping point."""
    path, summary = built
    whole = tmp_path / "whole"
    fn = TwoHalves()
    res = gen(whole, fn=fn)
    assert res["rollouts"] == summary["rollouts"] and fn.executed == summary["chunks"]
    assert fn.threads[0] == "MainThread" and all(t.startswith("prepare-chunk-") for t in fn.threads[1:])
    assert len(fn.threads) == summary["chunks"] + 1  # the one prepared past the stopping point
    part = tmp_path / "part"
    with pytest.raises(Killed):
        gen(part, fn=TwoHalves(kill_after=2))
    with pytest.raises(Killed, match="prepared half"):
        gen(part, fn=TwoHalves(fail_at=1))  # chunk 2 was prepared in the driver, chunk 3 on the thread
    assert sorted(p.name for p in (part / "chunks").iterdir()) == [f"chunk_{k:06d}" for k in range(3)]
    gen(part, fn=TwoHalves())
    for other in (whole, part):
        a, b = ds.load_rollouts(path), ds.load_rollouts(other)
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])


def test_cap_borrowing_records_and_warns(tmp_path):
    # positives only at small distances with no negatives there: borrowing is unavoidable
    def fn(key, b):
        rng = np.random.default_rng(np.asarray(key).tolist())
        dist = rng.uniform(0.0, 1.0, b)
        return {"label": dist < 0.3, "relation": np.full(b, "on_top"), "cog_distance": dist,
                "toy": np.full(b, "ball"), "other": np.full(b, "plate")}

    cfg = DatasetConfig(max_rollouts=64, distance_bins=4, borrow_fraction=0.0)
    with pytest.warns(UserWarning, match="negatives come from outside"):
        res = gen(tmp_path / "b", n=10, fn=fn, dataset_config=cfg)
    assert res["rollouts"] == 64
    assert res["borrowed"] == 5
    d = ds.load_dataset(tmp_path / "b")
    assert d["label"].sum() == 5
    # the borrowed negatives are the nearest ones to the positives' range (just above 0.3)
    r = ds.load_rollouts(tmp_path / "b")
    neg = np.sort(r["cog_distance"][~r["label"]])
    np.testing.assert_array_equal(np.sort(d["cog_distance"][~d["label"]]), neg[:5])
    assert json.loads((tmp_path / "b" / ds.SELECTION).read_text())["at_cap"] is True


def test_cap_without_positives_errors_with_rate(tmp_path):
    cfg = DatasetConfig(max_rollouts=40, distance_bins=4, borrow_fraction=0.0)
    p = tmp_path / "cap"
    with pytest.raises(ds.RolloutCapError, match=r"positive rate 0\.00%.*max_rollouts"):
        gen(p, fn=synthetic_rollout_fn(all_negative=True), dataset_config=cfg)
    assert len(list((p / "chunks").iterdir())) == 3  # ceil(40 / 16) chunks kept for a rerun


def test_int_codes_and_object_ids(tmp_path):
    names = ("ball", "cube", "plate")

    def fn(key, b):
        rng = np.random.default_rng(np.asarray(key).tolist())
        return {"label": np.arange(b) % 2, "relation": rng.integers(0, 3, b),
                "cog_distance": np.full(b, 0.5), "toy": np.zeros(b, int), "other": np.full(b, 2),
                "tag": np.array([b"x", b"y"] * (b // 2))}

    gen(tmp_path / "i", n=4, batch=4, fn=fn, object_names=names)
    d = ds.load_dataset(tmp_path / "i")
    assert set(d["toy"]) == {"ball"}
    assert set(d["other"]) == {"plate"}
    assert d["label"].dtype == bool
    assert set(d["tag"]) <= {"x", "y"}
    r = ds.load_rollouts(tmp_path / "i")
    import jax

    rng = np.random.default_rng(np.asarray(jax.random.fold_in(jax.random.PRNGKey(3), 0)).tolist())
    assert r["relation"].tolist() == np.asarray(ds.RELATIONS)[rng.integers(0, 3, 4)].tolist()


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kw, error, match",
    [
        ({"action": "fly"}, ds.DatasetError, "unknown action 'fly'"),
        ({"n": 1}, ConfigError, r"'dataset.n_samples' must be an integer in \[2, "),
        ({"n": 2.5}, ConfigError, r"'dataset.n_samples' must be an integer .*got 2.5"),
        ({"batch": 0}, ConfigError, r"'dataset.rollout_batch' must be an integer in \[1, "),
        ({"seed": -1}, ds.DatasetError, "seed must be in"),
    ],
)
def test_bad_arguments(tmp_path, kw, error, match):
    """Bad sizes are the dataset node's to refuse (when it is built), the rest generate_dataset's:
    one error naming the value, and no folder."""
    action = kw.pop("action", "lift")
    args = dict(n=10, seed=0, batch=4) | kw
    with pytest.raises(error, match=match):
        sizes = DatasetConfig(n_samples=args["n"], rollout_batch=args["batch"])
        ds.generate_dataset(tmp_path / "x", action, synthetic_rollout_fn(), args["seed"], progress=False,
                            dataset_config=sizes)
    assert not (tmp_path / "x").exists()


def test_the_sizes_come_from_the_dataset_node(tmp_path):
    """``n_samples`` and ``rollout_batch`` are read from the node: the rollout function is
    called with the node's batch, the selection has its n, and the sidecar's header and its
    recorded node say the same."""
    from relaff_jax.io import read_json

    seen = []

    def fn(key, batch):
        seen.append(batch)
        return synthetic_rollout_fn()(key, batch)

    node = dataclasses.replace(EXACT, n_samples=12, rollout_batch=8)
    res = ds.generate_dataset(tmp_path / "d", "lift", fn, 3, CFG, progress=False, dataset_config=node)
    assert set(seen) == {8} and res["rollouts"] == 8 * len(seen)
    d = ds.load_dataset(tmp_path / "d")
    assert len(d["label"]) == 12 and int(d["label"].sum()) == 6
    meta = read_json(tmp_path / "d" / ds.SIDECAR)
    assert (meta["n_samples"], meta["batch"]) == (12, 8)
    assert (meta["dataset_config"]["n_samples"], meta["dataset_config"]["rollout_batch"]) == (12, 8)


def test_unwritable_and_foreign_dirs(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(ds.DatasetError, match="cannot create"):
        gen(f / "sub")
    with pytest.raises(ds.DatasetError, match="not a directory"):
        gen(f)
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(ds.ForeignDirectoryError, match="not a relaff dataset"):
        gen(foreign)
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]
    with pytest.raises(ds.ForeignDirectoryError):
        ds.load_dataset(foreign)
    (tmp_path / "fake").mkdir()
    (tmp_path / "fake" / ds.SIDECAR).write_text('{"format": "something else"}')
    with pytest.raises(ds.ForeignDirectoryError):
        ds.info(tmp_path / "fake")
    with pytest.raises(ds.DatasetError, match="no such dataset"):
        ds.load_dataset(tmp_path / "missing")
    empty = tmp_path / "empty"
    empty.mkdir()  # an existing empty directory is fine
    gen(empty, n=4)
    assert ds.load_dataset(empty)["label"].sum() == 2


def test_bad_rollout_output_leaves_nothing(tmp_path):
    def no_label(key, b):
        out = synthetic_rollout_fn()(key, b)
        out.pop("label")
        return out

    def bad_relation(key, b):
        out = synthetic_rollout_fn()(key, b)
        out["relation"][0] = "under"
        return out

    def wrong_len(key, b):
        out = synthetic_rollout_fn()(key, b)
        out["qpos"] = out["qpos"][:-1]
        return out

    for fn, match in [(no_label, "lacks required field"), (bad_relation, "under"), (wrong_len, "'qpos'")]:
        with pytest.raises(ds.DatasetError, match=match):
            gen(tmp_path / "bad", fn=fn)
        assert not (tmp_path / "bad").exists()


def test_schema_change_between_chunks(tmp_path):
    calls: list = []

    def fn(key, b):
        out = synthetic_rollout_fn(calls=calls)(key, b)
        if len(calls) > 1:
            out["qpos"] = out["qpos"][:, :1]
        return out

    with pytest.raises(ds.DatasetError, match="'qpos'"):
        gen(tmp_path / "s", fn=fn)
    assert len(list((tmp_path / "s" / "chunks").iterdir())) == 1  # the good chunk is kept


def test_resume_mismatch(built, tmp_path):
    p = copy(built, tmp_path)
    for kw, what in [({"seed": 4}, "seed"), ({"n": 42}, "n_samples"), ({"batch": 8}, "batch")]:
        with pytest.raises(ds.DatasetMismatchError, match=what):
            gen(p, **kw)
    with pytest.raises(ds.DatasetMismatchError, match="action"):
        ds.generate_dataset(p, "push", synthetic_rollout_fn(), 3, CFG, progress=False, dataset_config=EXACT40)
    with pytest.raises(ds.DatasetMismatchError, match="config"):
        ds.generate_dataset(p, "lift", synthetic_rollout_fn(), 3, {"lift_height": 0.1}, progress=False, dataset_config=EXACT40)
    ds.load_dataset(p)  # untouched


def test_engine_recorded_and_resume_with_another_refused(built, tmp_path):
    """A dataset records its simulation engine; resuming it with the other one is refused with
    the fix in the message; a sidecar from before engines were recorded counts as MJX."""
    import dataclasses

    from relaff_jax.io import atomic_write_json, read_json

    p = copy(built, tmp_path)
    assert read_json(p / ds.SIDECAR)["engine"] == "mjx"
    native = dataclasses.replace(EXACT, engine="native")
    with pytest.raises(ds.DatasetMismatchError, match=r"generated with the mjx engine.*--engine mjx"):
        gen(p, dataset_config=native)
    meta = read_json(p / ds.SIDECAR)
    del meta["engine"]  # as written before the native engine existed
    atomic_write_json(p / ds.SIDECAR, meta)
    assert gen(p)["new_chunks"] == 0  # still resumable (complete) as MJX
    with pytest.raises(ds.DatasetMismatchError, match="mjx engine"):
        gen(p, dataset_config=native)
    with pytest.raises(UserError, match="'dataset.engine' must be one of mjx, native, got 'gpu'"):  # the node
        gen(tmp_path / "x", dataset_config=dataclasses.replace(EXACT, engine="gpu"))
    assert not (tmp_path / "x").exists()


def test_concurrent_writer_refused(built, tmp_path):
    p = copy(built, tmp_path)
    with store.writer_lock(p):
        with pytest.raises(ds.DatasetError, match="another process"):
            gen(p)


def _damage(p: Path, how: str) -> None:
    c = p / "chunks"
    if how == "missing middle chunk":
        shutil.rmtree(c / "chunk_000001")
    elif how == "missing last chunk":
        shutil.rmtree(sorted(c.iterdir())[-1])
    elif how == "corrupt chunk meta":
        (c / "chunk_000000" / "meta.json").write_text("{not json")
    elif how == "corrupt chunk data":
        meta = json.loads((c / "chunk_000000" / "meta.json").read_text())
        meta["arrays"]["qpos"]["sha256"] = "0" * 64  # as if the stored bytes had changed
        (c / "chunk_000000" / "meta.json").write_text(json.dumps(meta))
    elif how == "damaged orbax files":
        for f in (c / "chunk_000000" / "arrays").rglob("*"):
            if f.is_file() and f.stat().st_size > 0:
                f.write_bytes(b"\0" * 7)
    elif how == "flipped byte in orbax data":
        for f in (c / "chunk_000000" / "arrays").rglob("*"):
            if f.is_file() and f.parent.name == "d":
                b = bytearray(f.read_bytes())
                b[len(b) // 2] ^= 0xFF
                f.write_bytes(bytes(b))
    elif how == "missing orbax dir":
        shutil.rmtree(c / "chunk_000000" / "arrays")
    elif how == "missing index":
        (p / ds.SELECTION).unlink()
    elif how == "corrupt index":
        (p / ds.SELECTION).write_text('{"selected": [0, 1')
    elif how == "edited index":
        idx = json.loads((p / ds.SELECTION).read_text())
        idx["selected"][0] = idx["selected"][1] - 1 if idx["selected"][0] + 1 < idx["selected"][1] else 10**6
        (p / ds.SELECTION).write_text(json.dumps(idx))
    elif how == "corrupt sidecar":
        (p / ds.SIDECAR).write_text("{{")
    elif how == "missing sidecar":
        (p / ds.SIDECAR).unlink()
    elif how == "swapped chunks":
        (c / "chunk_000000").rename(c / "tmp")
        (c / "chunk_000001").rename(c / "chunk_000000")
        (c / "tmp").rename(c / "chunk_000001")


# orbax leaves an "Event loop is closed" in a background thread after a failed restore
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.parametrize(
    "how, match",
    [
        ("missing middle chunk", r"chunk\(s\) \[1\] missing"),
        ("missing last chunk", "sidecar records"),
        ("corrupt chunk meta", "metadata missing or corrupt"),
        ("corrupt chunk data", "'qpos' is corrupt"),
        ("damaged orbax files", "chunk_000000"),
        ("flipped byte in orbax data", "chunk_000000"),
        ("missing orbax dir", "orbax cannot read"),
        ("missing index", "selection.json is missing"),
        ("corrupt index", "selection.json is corrupt"),
        ("edited index", "does not match"),
        ("corrupt sidecar", "sidecar relaff_dataset.json is corrupt"),
        ("missing sidecar", "sidecar relaff_dataset.json is missing"),
        ("swapped chunks", "rollout ids"),
    ],
)
def test_truncated_or_corrupt(built, tmp_path, how, match):
    p = copy(built, tmp_path)
    _damage(p, how)
    with pytest.raises(ds.CorruptDatasetError, match=match):
        ds.load_dataset(p)
    with pytest.raises(ds.CorruptDatasetError):
        ds.info(p)
    if how not in ("missing index", "corrupt index", "edited index"):
        with pytest.raises(ds.CorruptDatasetError):  # resuming refuses too, and never deletes data
            gen(p)
        assert p.exists()


# ----------------------------------------------------------------------------- info


def test_info_values_and_cli(built, capsys):
    path, summary = built
    d = ds.info(path)
    data, r = ds.load_dataset(path), ds.load_rollouts(path)
    assert d["action"] == "lift"
    assert d["n"] == 40
    assert d["positive_rate"] == 0.5
    assert d["rollouts"] == summary["rollouts"] == len(r["label"])
    assert d["status"] == "complete"
    for rel in ds.RELATIONS:
        labs = [l for l, x in zip(data["label"], data["relation"]) if x == rel]
        assert d["count_by_relation"][rel] == {"n": len(labs), "positives": sum(labs)}
        assert d["positive_rate_by_relation"][rel] == (sum(labs) / len(labs) if labs else None)
        labs = [l for l, x in zip(r["label"], r["relation"]) if x == rel]
        assert d["rollouts_positive_rate_by_relation"][rel] == pytest.approx(sum(labs) / len(labs))
    pairs = {f"{t}/{o}" for t, o in zip(data["toy"], data["other"])}
    assert set(d["positive_rate_by_pair"]) == pairs
    assert sum(c["n"] for c in d["count_by_pair"].values()) == 40
    assert d["features"] is None
    assert d["borrowed"] == 0
    assert d["config"] == CFG
    assert d["versions"]["orbax-checkpoint"]

    parser = argparse.ArgumentParser()
    cli_data.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["info", str(path), "--json"])
    assert args.func(args) == 0
    j = json.loads(capsys.readouterr().out)
    assert j["n"] == 40
    assert j["positive_rate_by_relation"] == d["positive_rate_by_relation"]
    args = parser.parse_args(["info", str(path)])
    assert args.func(args) == 0
    text = capsys.readouterr().out
    assert "on_top" in text
    assert "features: none" in text
    assert f"{summary['rollouts']} rollouts" in text


def test_info_while_generating(tmp_path):
    p = tmp_path / "g"
    with pytest.raises(Killed):
        gen(p, fn=synthetic_rollout_fn(kill_after=1))
    d = ds.info(p)
    assert d["status"] == "generating"
    assert d["n"] == 0
    assert d["rollouts"] == 16
    assert d["positive_rate"] is None
    assert d["rollouts_positive_rate"] is not None
    assert "generating" in ds.format_info(d)


# ----------------------------------------------------------------------------- features


def test_a_sidecar_of_the_old_generate_record_shape_resumes(tmp_path):
    """relaff generate recorded {"action": cfg}, reproduce {"action": name, "action_config": cfg};
    both write the second now, and a dataset with the first is read in it, so it resumes."""
    from relaff_jax.io import atomic_write_json, read_json

    new_shape = {"action": "lift", "action_config": CFG}
    p = tmp_path / "d"
    with pytest.raises(Killed):
        ds.generate_dataset(p, "lift", synthetic_rollout_fn(kill_after=2), 3, new_shape, progress=False,
                            dataset_config=EXACT40)
    meta = read_json(p / ds.SIDECAR)
    meta["config"] = {"action": CFG}  # what relaff generate wrote before
    atomic_write_json(p / ds.SIDECAR, meta)
    assert store.read_sidecar(p)["config"] == new_shape
    res = ds.generate_dataset(p, "lift", synthetic_rollout_fn(), 3, new_shape, progress=False,
                              dataset_config=EXACT40)
    assert res["new_chunks"] > 0
    with pytest.raises(ds.DatasetMismatchError, match="config"):
        ds.generate_dataset(p, "lift", synthetic_rollout_fn(), 3, {"action": "lift", "action_config": {}},
                            progress=False, dataset_config=EXACT40)


def test_add_features_round_trip_and_resume(built, tmp_path):
    p = copy(built, tmp_path)
    with pytest.raises(Killed):
        ds.add_features(p, feature_fn(kill_after=2), batch=12, progress=False, config_dict={"voxel": 0.0125})
    assert "pca" not in ds.load_dataset(p)  # unfinished features are not served
    assert ds.info(p)["features"]["status"] == "generating"
    sizes: list = []
    res = ds.add_features(p, feature_fn(sizes=sizes), batch=12, progress=False, config_dict={"voxel": 0.0125})
    assert sizes == [12, 12]
    assert res["new_chunks"] == 2
    assert res["chunks"] == 4  # 40 = 12+12+12+4 (padded)
    d = ds.load_dataset(p)
    want = feature_fn()({k: v for k, v in d.items() if k not in ("pca", "rhf", "unseen", "action")})
    assert d["pca"].shape == (40, 18)
    assert d["rhf"].shape == (40, 300)
    assert d["unseen"].shape == (40, 2)
    for k in ("pca", "rhf", "unseen"):
        np.testing.assert_array_equal(d[k], want[k])
    f = ds.info(p)["features"]
    assert f["arrays"]["pca"]["shape"] == [40, 18]
    assert f["arrays"]["unseen"]["dtype"] == "bool"
    assert f["unseen_samples"] == int(want["unseen"].any(axis=1).sum())
    assert f["unseen_by_column"] == want["unseen"].sum(axis=0).tolist()
    # finished: rerun is a no-op; other config is refused unless overwrite
    assert ds.add_features(p, feature_fn(kill_after=0), batch=12, progress=False, config_dict={"voxel": 0.0125})["new_chunks"] == 0
    with pytest.raises(ds.DatasetMismatchError, match="voxel"):
        ds.add_features(p, feature_fn(), batch=12, progress=False, config_dict={"voxel": 0.02})
    res = ds.add_features(p, feature_fn(), batch=40, progress=False, config_dict={"voxel": 0.02}, overwrite=True)
    assert res["chunks"] == 1
    np.testing.assert_array_equal(ds.load_dataset(p)["pca"], want["pca"])
    # chunks without features.json (an overwrite killed after removing it) are ignored, then cleaned
    (p / "features.json").rename(tmp_path / "features.json")
    assert "pca" not in ds.load_dataset(p)
    assert ds.info(p)["features"] is None
    ds.add_features(p, feature_fn(), batch=16, progress=False)
    assert sorted(x.name for x in (p / "features").iterdir()) == ["chunk_000000", "chunk_000001", "chunk_000002"]
    np.testing.assert_array_equal(ds.load_dataset(p)["rhf"], want["rhf"])
    # a lost feature chunk is detected
    shutil.rmtree(p / "features" / "chunk_000002")
    with pytest.raises(ds.CorruptDatasetError, match="truncated features"):
        ds.load_dataset(p)
    shutil.rmtree(p / "features" / "chunk_000000")
    with pytest.raises(ds.CorruptDatasetError, match=r"chunk\(s\) \[0\] missing"):
        ds.info(p)


def test_add_features_bad_input(built, tmp_path):
    p = copy(built, tmp_path)
    with pytest.raises(ds.DatasetError, match="collides"):
        ds.add_features(p, lambda s: {"label": s["label"]}, batch=8, progress=False)
    with pytest.raises(ds.DatasetError, match="'unseen' must be bool"):
        ds.add_features(p, lambda s: {"unseen": np.zeros((len(s["label"]), 2))}, batch=8, progress=False)
    with pytest.raises(ds.DatasetError, match="leading axis 8"):
        ds.add_features(p, lambda s: {"pca": np.zeros((3, 18))}, batch=8, progress=False)
    with pytest.raises(ds.DatasetError, match="batch must be >= 1"):
        ds.add_features(p, feature_fn(), batch=0, progress=False)
    assert not list((p / "features").glob("chunk_*"))
    with pytest.raises(ds.ForeignDirectoryError):
        ds.add_features(tmp_path, feature_fn(), batch=8, progress=False)


def test_add_features_threads(built, tmp_path):
    """Chunks computed on several threads: the arrays of one thread; a chunk finished early waits
    for those before it, so a failure leaves no chunk after a gap."""
    import threading
    import time

    one, three = copy(built, tmp_path / "one"), copy(built, tmp_path / "three")
    ds.add_features(one, feature_fn(), batch=8, progress=False, threads=1)
    ds.add_features(three, feature_fn(), batch=8, progress=False, threads=3)
    a, b = ds.load_dataset(one), ds.load_dataset(three)
    for k in ("pca", "rhf", "unseen"):
        np.testing.assert_array_equal(a[k], b[k])
    assert ds.info(three)["features"]["chunks"] == 5
    base, calls, lock = feature_fn(), [], threading.Lock()

    def first_fails_late(s):  # the first call sleeps, then fails; the others finish meanwhile
        with lock:
            calls.append(len(calls))
            me = calls[-1]
        if me == 0:
            time.sleep(0.5)
            raise Killed("simulated kill")
        return base(s)

    p = copy(built, tmp_path / "fail")
    with pytest.raises(Killed):
        ds.add_features(p, first_fails_late, batch=8, progress=False, threads=3)
    assert len(calls) >= 3  # chunks 1 and 2 were computed beside chunk 0
    assert not list((p / "features").glob("chunk_*"))  # and not written: chunk 0 never landed
    ds.add_features(p, feature_fn(), batch=8, progress=False, threads=2)  # the rerun completes it
    np.testing.assert_array_equal(ds.load_dataset(p)["rhf"], a["rhf"])
    with pytest.raises(ds.DatasetError, match="threads must be >= 1"):
        ds.add_features(p, feature_fn(), batch=8, progress=False, threads=0)


def test_progress_bar_and_report(tmp_path, capsys):
    res = ds.generate_dataset(tmp_path / "p", "take", synthetic_rollout_fn(), 0, {}, progress=True,
                              dataset_config=dataclasses.replace(EXACT, n_samples=6, rollout_batch=8))
    err = capsys.readouterr().err
    assert "take samples" in err  # the tqdm bar, after its compile phase
    assert f"6 samples selected from {res['rollouts']} rollouts" in err
    sizes: list = []
    ds.add_features(tmp_path / "p", feature_fn(sizes=sizes), batch=4, progress=True)
    assert "features" in capsys.readouterr().err
    assert sizes == [4, 4]


def test_sigkill_mid_run_then_resume(built, tmp_path):
    """A real SIGKILL of a generating process (at whatever point it is), then a rerun."""
    import os
    import signal
    import subprocess
    import sys
    import time

    path, summary = built
    target = tmp_path / "killed"
    code = (
        "import sys, time; sys.path[:0] = [%r]\n"
        "import helpers.standins as t\n"
        "fn = t.synthetic_rollout_fn()\n"
        "def slow(key, b):\n"
        "    time.sleep(0.05)\n"
        "    return fn(key, b)\n"
        "t.gen(%r, fn=slow)\n"
    ) % (str(TESTS), str(target))
    proc = subprocess.Popen([sys.executable, "-c", code], env=dict(os.environ, JAX_PLATFORMS="cpu"))
    try:
        deadline = time.time() + 60
        while not (target / "chunks" / "chunk_000003").exists() and time.time() < deadline and proc.poll() is None:
            time.sleep(0.01)
        time.sleep(0.03)  # land somewhere inside a later chunk's simulation or save
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert (target / "chunks" / "chunk_000003").exists()
    res = gen(target)
    assert res["rollouts"] == summary["rollouts"]
    a, b = ds.load_rollouts(path), ds.load_rollouts(target)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    assert not [p for p in (target / "chunks").iterdir() if p.name.startswith(".")]


# ----------------------------------------------------------------------------- fault-probe regressions


def test_lock_race_loser_leaves_winner_folder(tmp_path, monkeypatch):
    """A creates the folder, B takes the lock first: A's failure must not delete B's folder."""
    import contextlib

    p = tmp_path / "race"
    real = store.prepare_dir
    winner = contextlib.ExitStack()

    def prepare_then_lose(path):
        created = real(path)
        winner.enter_context(store.writer_lock(path))  # B wins the lock race ...
        (path / ds.SIDECAR).write_text("{}")  # ... and starts writing
        return created

    monkeypatch.setattr(generate, "prepare_dir", prepare_then_lose)
    with winner:
        with pytest.raises(ds.DatasetError, match="another process"):
            gen(p)
        assert (p / ds.SIDECAR).exists()  # B's folder is untouched
    monkeypatch.undo()
    # a creator that fails on its own (under its lock) still leaves nothing behind
    with pytest.raises(ds.DatasetError, match="lacks required field"):
        gen(tmp_path / "own", fn=lambda key, b: {"label": np.zeros(b, bool)})
    assert not (tmp_path / "own").exists()


def test_writer_lock_refuses_removed_lock_file(built, tmp_path, monkeypatch):
    """A writer that waited on a lock file which the previous holder then removed (with the
    folder it created) holds a lock that excludes nobody: it must refuse."""
    import fcntl

    p = copy(built, tmp_path)
    real = fcntl.flock

    def flock_after_removal(fd, op):
        (p / ds.LOCK).unlink()  # the previous holder's remove_created
        (p / ds.LOCK).write_text("")  # and a newcomer's fresh lock file
        return real(fd, op)

    monkeypatch.setattr(fcntl, "flock", flock_after_removal)
    with pytest.raises(ds.DatasetError, match="removed this dataset folder"):
        with store.writer_lock(p):
            pass
    monkeypatch.undo()
    with store.writer_lock(p):  # the current lock file works
        pass


def _corrupt_feature_chunk(p: Path, k: int = 1) -> None:
    for f in (p / "features" / f"chunk_{k:06d}" / "arrays").rglob("*"):
        if f.is_file() and f.parent.name == "d":
            b = bytearray(f.read_bytes())
            b[len(b) // 2] ^= 0xFF
            f.write_bytes(bytes(b))


def test_features_status_and_overwrite_recovers_corrupt_chunk(built, tmp_path):
    p = copy(built, tmp_path)
    cfg = {"voxel": 0.0125}
    assert ds.features_status(p, 12, cfg)[0] == "absent"
    with pytest.raises(Killed):
        ds.add_features(p, feature_fn(kill_after=2), batch=12, progress=False, config_dict=cfg)
    assert ds.features_status(p, 12, cfg) == ("partial", "2 of 4 feature chunks")
    ds.add_features(p, feature_fn(), batch=12, progress=False, config_dict=cfg)
    assert ds.features_status(p, 12, cfg)[0] == "complete"
    state, why = ds.features_status(p, 12, {"voxel": 0.02})
    assert state == "stale"
    assert "voxel" in why
    assert ds.features_status(p, 16, cfg)[0] == "stale"
    want = ds.load_dataset(p)["rhf"]
    _corrupt_feature_chunk(p, 1)
    state, why = ds.features_status(p, 12, cfg)
    assert state == "corrupt"
    assert "chunk_000001" in why
    with pytest.raises(ds.CorruptDatasetError, match="overwrite=True"):
        ds.add_features(p, feature_fn(), batch=12, progress=False, config_dict=cfg)
    sizes: list = []
    res = ds.add_features(p, feature_fn(sizes=sizes), batch=12, progress=False, config_dict=cfg, overwrite=True)
    assert res["new_chunks"] == 4
    assert len(sizes) == 4
    assert ds.features_status(p, 12, cfg)[0] == "complete"
    np.testing.assert_array_equal(ds.load_dataset(p)["rhf"], want)
    (p / ds.FEATURES_SIDECAR).write_text("{oops")
    assert ds.features_status(p, 12, cfg)[0] == "corrupt"


def test_dataset_status(built, tmp_path):
    path, summary = built
    expected = {"action": "lift", "n_samples": 40, "seed": 3, "batch": 16, "config": CFG}
    assert ds.dataset_status(path, expected) == ("complete", f"40 samples from {summary['rollouts']} rollouts")
    assert ds.dataset_status(tmp_path / "none", expected)[0] == "absent"
    (tmp_path / "empty").mkdir()
    assert ds.dataset_status(tmp_path / "empty", expected)[0] == "absent"
    state, why = ds.dataset_status(path, dict(expected, seed=4))
    assert state == "stale"
    assert "seed" in why
    part = tmp_path / "part"
    with pytest.raises(Killed):
        gen(part, fn=synthetic_rollout_fn(kill_after=2))
    assert ds.dataset_status(part, expected)[0] == "partial"
    for how in ("flipped byte in orbax data", "edited index", "corrupt sidecar"):
        p = tmp_path / how.replace(" ", "_")
        shutil.copytree(path, p)
        _damage(p, how)
        assert ds.dataset_status(p, expected)[0] == "corrupt", how
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "x.txt").write_text("mine")
    with pytest.raises(ds.ForeignDirectoryError):
        ds.dataset_status(foreign, expected)


def test_corrupt_chunk_read_prints_no_event_loop_error(built, tmp_path):
    """orbax's restore leaves tensorstore futures on a closed asyncio loop after a failed read;
    their collection printed "RuntimeError: Event loop is closed" after our clear message."""
    import os
    import subprocess
    import sys

    p = copy(built, tmp_path)
    _damage(p, "flipped byte in orbax data")
    code = (
        "import gc, sys\n"
        "from relaff_jax import data as D\n"
        "for _ in range(3):\n"
        "    try:\n"
        "        D.load_dataset(sys.argv[1])\n"
        "    except D.CorruptDatasetError as e:\n"
        "        print('clear:', e, file=sys.stderr)\n"
        "    gc.collect()\n"
    )
    res = subprocess.run([sys.executable, "-c", code, str(p)], capture_output=True, text=True, timeout=300,
                         env=dict(os.environ, JAX_PLATFORMS="cpu"), cwd=str(ROOT))
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("clear: chunk") == 3
    assert "Event loop is closed" not in res.stderr
    assert "Traceback" not in res.stderr


def test_a_chunk_that_does_not_read_back_never_lands(tmp_path, monkeypatch):
    """The race of a killed driver's task on a worker: the restarted driver's ``clean_tmp``
    removes the task's temporary folder while orbax writes into it, orbax finishes an
    incomplete checkpoint, and the rename would land it. ``write_chunk`` reads the chunk
    back first, so the writer fails and nothing appears under the chunk's name."""
    real = store._checkpointer()

    class Damaging:
        def save(self, where, tree):
            real.save(where, tree)
            for f in Path(where).iterdir():  # what a concurrent rmtree leaves: files missing
                if f.is_file():
                    f.unlink()

    monkeypatch.setattr(store, "_checkpointer", lambda: Damaging())
    path = tmp_path / "chunk_000000"
    with pytest.raises(ds.CorruptDatasetError, match="chunk"):
        store.write_chunk(path, {"label": np.zeros(4, bool)}, {"chunk": 0})
    assert not path.exists()
    assert not list(tmp_path.iterdir())
    monkeypatch.undo()
    store.write_chunk(path, {"label": np.zeros(4, bool)}, {"chunk": 0})  # the real writer lands
    assert store.read_chunk(path)[0]["label"].shape == (4,)


class _RecordingBar:
    """Stands in for the tqdm bar: records every count and description."""

    def __init__(self, total, desc):
        self.total, self.n, self.counts, self.descs = total, 0, [], [desc]

    def update(self, k):
        self.n += k
        self.counts.append(self.n)

    def set_postfix(self, **kw):
        pass

    def set_description(self, desc):
        self.descs.append(desc)

    def close(self):
        pass


def test_progress_bar_counts_samples_in_hand_and_ends_at_n(tmp_path, monkeypatch):
    bars = []

    def fake_bar(progress, total, desc, unit="pos"):
        bars.append(_RecordingBar(total, desc))
        return bars[-1]

    monkeypatch.setattr(generate, "progress_bar", fake_bar)
    res = ds.generate_dataset(tmp_path / "lift", "lift", synthetic_rollout_fn(), 3, CFG,
                              progress=True, dataset_config=EXACT40)
    (bar,) = bars
    assert bar.total == 40
    # the first chunk (the compile) is its own phase, then the bar counts samples
    assert bar.descs == ["lift: compiling, first chunk", "lift samples"]
    assert bar.counts[0] == 0
    assert bar.counts[-1] == 40
    # one count per selection attempt: one before the first chunk and one after each chunk
    assert len(bar.counts) == res["chunks"] + 1
    # matching negatives counts: the bar is below 40 until the last chunk, never at 100 % early
    assert all(c < 40 for c in bar.counts[:-1])


def test_samples_in_hand_hand_worked():
    from types import SimpleNamespace

    lab = np.array([1, 1, 1, 0, 0, 0, 0], bool)
    ok = np.array([1, 1, 0, 1, 1, 1, 0], bool)
    # no selection yet: eligible positives (2) capped at n // 2 = 5, eligible negatives 3 of 5
    assert generate.samples_in_hand(None, lab, ok, 10, 0.0) == 5
    assert generate.samples_in_hand(None, lab, ok, 4, 0.0) == 4
    sel = SimpleNamespace(borrowed=7, n_negative=20)
    assert generate.samples_in_hand(sel, lab, ok, 40, 0.0) == 33  # 7 borrowed negatives still owed
    assert generate.samples_in_hand(sel, lab, ok, 40, 0.35) == 40  # 7 <= floor(0.35 * 20): none owed
    assert generate.samples_in_hand(sel, lab, ok, 40, 0.2) == 37  # floor(4) allowed, 3 owed


def test_generation_progress_of_a_killed_run_reads_samples_in_hand(tmp_path):
    from relaff_jax.data.status import generation_progress

    path = tmp_path / "lift"
    with pytest.raises(Killed):
        gen(path, n=40, fn=synthetic_rollout_fn(kill_after=2))
    meta = store.read_sidecar(path)
    c = meta["counts"]
    assert c["chunks"] == 2
    assert 0 < c["in_hand"] < 40
    assert generation_progress(path, 40) == c["in_hand"] / 40


def test_native_settle_recorded_and_old_native_refused(tmp_path):
    """A native dataset records the C settle; one begun before it (no ``settle``: its scenes
    were settled by MJX) is refused rather than resumed with C-settled chunks."""
    import dataclasses

    from relaff_jax.io import atomic_write_json, read_json
    from relaff_jax.sim.native.settle import SETTLE_NAME

    assert generate.SETTLE_OF_ENGINE["native"] == SETTLE_NAME
    native = dataclasses.replace(EXACT, engine="native")
    p = tmp_path / "n"
    gen(p, dataset_config=native)
    meta = read_json(p / ds.SIDECAR)
    assert meta["settle"] == SETTLE_NAME
    del meta["settle"]
    atomic_write_json(p / ds.SIDECAR, meta)
    with pytest.raises(ds.DatasetMismatchError, match=f"settled by mjx.*{SETTLE_NAME}"):
        gen(p, dataset_config=native)
