"""`relaff reproduce --status` from the datasets' status manifests equals the reference path
that reads every chunk (``status(out, reference=True)``), for complete, partial, stale and
corrupt run folders; a complete folder's status reads no chunk array.

Numpy stand-ins replace the simulation and the perception (as in the driver's own tests), so
the real dataset, experiment and report stages run in seconds.
"""
import json
import os
import shutil

import numpy as np
import pytest

from relaff_jax import data as D
from relaff_jax import reproduce as R
from relaff_jax.constants import ACTIONS
from relaff_jax.data import load as data_load
from relaff_jax.data import status as data_status
from relaff_jax.data import store as data_store
from relaff_jax.stages import features as stage_features

ACTS = ("lift", "pour")
SETTINGS = {"reproduce.actions": ACTS, "dataset.n_samples": 24, "experiment.forest.base_trees": 3,
            "experiment.forest.max_trees": 3, "experiment.sizes": (4, 10), "reproduce.examples_per_action": 0}


def stand_in_rollouts(action, batch, stop_after=None):
    calls = [0]

    def fn(key, b):
        calls[0] += 1
        if stop_after is not None and calls[0] > stop_after:
            raise KeyboardInterrupt
        rng = np.random.default_rng(np.asarray(key).tolist() + [7 + ACTIONS.index(action)])
        rel = rng.integers(0, 3, b)
        return {"label": rng.random(b) < 0.5, "relation": rel.astype(np.int32),
                "cog_distance": rng.uniform(0.05, 1.0, b).astype(np.float32),
                "toy": np.asarray(("ball", "cube"))[rng.integers(0, 2, b)],
                "other": np.asarray(("plate", "cup"))[rng.integers(0, 2, b)]}

    return fn, {"stand_in": action}, None


def stand_in_config(seed):
    return {"kind": "stand-in features", "seed": seed}


def stand_in_features(seed):
    def compute(s):
        n = len(s["label"])
        rng = np.random.default_rng([seed, int(s["rollout"][0])])
        pca = rng.normal(size=(n, 18)).astype(np.float32)
        pca[:, 3] += s["label"]
        return {"pca": pca, "rhf": rng.random((n, 300)).astype(np.float32), "unseen": np.zeros((n, 2), bool)}

    return compute, stand_in_config(seed)


HOOKS = R.Hooks(rollout_factory=stand_in_rollouts, feature_factory=stand_in_features, feature_config=stand_in_config)


def reproduce(out, **kw):
    return R.reproduce(out, "tiny", 5, hooks=HOOKS, overrides=SETTINGS, jobs=1, progress=False, **kw)


@pytest.fixture(autouse=True)
def stand_in_perception(monkeypatch):
    # R.status rebuilds the run from run.json with the tree's own perception config
    monkeypatch.setattr(stage_features, "factories_for", lambda cfg: (stand_in_features, stand_in_config))


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    out = tmp_path_factory.mktemp("status") / "run"
    mp = pytest.MonkeyPatch()
    mp.setattr(stage_features, "factories_for", lambda cfg: (stand_in_features, stand_in_config))
    reproduce(out)
    mp.undo()
    return out


def no_chunk_reads(monkeypatch):
    def refuse(path):
        raise AssertionError(f"status read the chunk {path}")

    for mod in (data_store, data_load, data_status):
        monkeypatch.setattr(mod, "read_chunk", refuse)


def both(out, monkeypatch=None):
    ref = R.status(out, reference=True)
    if monkeypatch is not None:
        no_chunk_reads(monkeypatch)
    return ref, R.status(out)


def flip_byte(chunk):
    f = next(p for p in sorted((chunk / "arrays").rglob("*")) if p.is_file() and p.parent.name == "d")
    st = f.stat()
    b = bytearray(f.read_bytes())
    b[len(b) // 2] ^= 0xFF
    f.write_bytes(bytes(b))
    return f, st


def test_complete_folder_status_reads_no_chunk_and_equals_the_reference(done, monkeypatch):
    ref, new = both(done, monkeypatch)
    assert new == ref
    assert {s: st.state for s, st in new.items()} == dict.fromkeys(R.STAGES, "complete")
    assert new["generate"].why == "2 of 2 complete"
    # the manifest's fingerprints are the ones the experiment recorded from the loaded arrays
    meta = json.loads((done / "results" / "experiment.json").read_text())
    for a in ACTS:
        fp = data_status.manifest_fingerprint(done / "data" / a)
        assert {s: fp[s] for s in meta["fingerprint"]} == {s: v[a] for s, v in meta["fingerprint"].items()}


def test_a_dataset_without_a_manifest_falls_back_to_reading_it(done, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(done, out)
    os.unlink(out / "data" / "pour" / data_status.MANIFEST)  # a dataset from before manifests
    assert data_status.manifest_fingerprint(out / "data" / "pour") is None
    assert data_status.manifest_fingerprint(out / "data" / "lift") is not None
    ref, new = both(out)
    assert new == ref and new["experiment"].state == "complete"


def test_partial_folders_read_no_chunk(tmp_path, monkeypatch):
    out = tmp_path / "run"
    hooks = R.Hooks(rollout_factory=lambda a, b: stand_in_rollouts(a, b, stop_after=1),
                    feature_factory=stand_in_features, feature_config=stand_in_config)
    with pytest.raises(KeyboardInterrupt):
        R.reproduce(out, "tiny", 5, hooks=hooks, overrides=SETTINGS, jobs=1, progress=False)
    ref, new = both(out, monkeypatch)
    assert new == ref
    assert new["generate"].state == "partial" and "rollouts in 1 chunks, generation not finished" in new["generate"].why
    assert new["experiment"].state == "absent"
    monkeypatch.undo()

    def killed_features(seed):
        compute, cfg = stand_in_features(seed)
        calls = [0]

        def fn(s):
            calls[0] += 1
            if calls[0] > 1:
                raise KeyboardInterrupt
            return compute(s)

        return fn, cfg

    out = tmp_path / "features"
    hooks = R.Hooks(rollout_factory=stand_in_rollouts, feature_factory=killed_features, feature_config=stand_in_config)
    with pytest.raises(KeyboardInterrupt):
        R.reproduce(out, "tiny", 5, hooks=hooks, overrides=SETTINGS, jobs=1, progress=False)
    monkeypatch.setattr(stage_features, "factories_for", lambda cfg: (stand_in_features, stand_in_config))
    ref, new = both(out, monkeypatch)
    assert new == ref
    assert new["generate"].state == "complete"
    assert new["features"].state == "partial" and "1 of" in new["features"].why


def test_a_damaged_chunk_of_a_partial_dataset_is_found_by_the_resume(tmp_path):
    """The metadata path counts a partial dataset's rows from its chunks' meta.json: a
    flipped array byte is seen by the reference path and by the resume, which reads every
    chunk before simulating more."""
    out = tmp_path / "run"
    hooks = R.Hooks(rollout_factory=lambda a, b: stand_in_rollouts(a, b, stop_after=2),
                    feature_factory=stand_in_features, feature_config=stand_in_config)
    with pytest.raises(KeyboardInterrupt):
        R.reproduce(out, "tiny", 5, hooks=hooks, overrides=SETTINGS, jobs=1, progress=False)
    flip_byte(out / "data" / "lift" / "chunks" / "chunk_000000")
    ref, new = both(out)
    assert ref["generate"].state == "corrupt" and "chunk_000000" in ref["generate"].why
    assert new["generate"].state == "partial"
    with pytest.raises(R.ReproduceError, match="redo-dataset lift"):
        reproduce(out)


def test_stale_folder_after_a_changed_setting(done, tmp_path, monkeypatch):
    out = tmp_path / "run"
    shutil.copytree(done, out)
    log = json.loads((out / R.RUN_LOG).read_text())
    log["config"]["experiment"]["reps_pca"] = 3
    (out / R.RUN_LOG).write_text(json.dumps(log))
    ref, new = both(out, monkeypatch)
    assert new == ref
    assert new["generate"].state == "complete" and new["features"].state == "complete"
    assert new["experiment"].state == "stale" and "reps_pca" in new["experiment"].why
    assert new["report"].state == "stale"


def test_corrupt_chunks_are_found_when_the_file_changed(done, tmp_path):
    for part in ("chunks", "features"):
        out = tmp_path / part
        shutil.copytree(done, out)
        flip_byte(out / "data" / "lift" / part / "chunk_000000")
        ref, new = both(out)
        assert new == ref
        stage = "generate" if part == "chunks" else "features"
        assert new[stage].state == "corrupt" and "lift" in new[stage].why
    out = tmp_path / "gone"
    shutil.copytree(done, out)
    shutil.rmtree(out / "data" / "pour" / "chunks" / "chunk_000000")
    ref, new = both(out)
    assert new == ref and new["generate"].state == "corrupt"


def test_a_flip_that_keeps_size_and_mtime_costs_the_verifying_rerun(done, tmp_path):
    """The metadata path trusts a file whose size and mtime are as recorded (bit rot, or a
    writer that restored the mtime): only the reference path sees it. A rerun verifies every
    chunk (``reproduce`` trusts no manifest), so it finds and recomputes it."""
    out = tmp_path / "run"
    shutil.copytree(done, out)
    f, st = flip_byte(out / "data" / "lift" / "features" / "chunk_000000")
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))
    ref, new = both(out)
    assert ref["features"].state == "corrupt"
    assert new["features"].state == "complete"
    log = reproduce(out)
    assert log["runs"][-1]["stages"]["features"]["status"] == "ran"
    np.testing.assert_array_equal(D.load_dataset(out / "data" / "lift")["pca"],
                                  D.load_dataset(done / "data" / "lift")["pca"])
    ref, new = both(out)
    assert new == ref and new["features"].state == "complete"
