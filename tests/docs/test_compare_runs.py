"""benchmarks/compare_runs.py: two run folders compared key by key, stage by stage, on folders
made by the stand-in stages (tests/helpers/standins.py) and then altered by hand, so each
difference and the stage it first appears in are known."""
import json
import shutil
import sys

import numpy as np
import pytest

from helpers import ROOT, standins

sys.path.insert(0, str(ROOT / "benchmarks"))

import compare_runs  # noqa: E402
from relaff_jax import data as ds  # noqa: E402


@pytest.fixture(scope="module")
def run_a(tmp_path_factory):
    """A finished stand-in run (two actions): datasets, features, both spaces, the report."""
    out = tmp_path_factory.mktemp("compare") / "a"
    standins.run(out, ["lift", "move"], seed=3)
    return out


def _rows(rows):
    return {(r["stage"], r["item"]): r for r in rows}


def test_same_values_nan_text_dtype_shape():
    assert compare_runs.same(np.array([1.0, np.nan]), np.array([1.0, np.nan]))[0]  # NaN = NaN
    ok, why = compare_runs.same(np.array([1.0, np.nan, 3.0]), np.array([1.0, 2.0, 3.5]))
    assert not ok and why == "2 of 3 differ, max |diff| 0.5"
    assert compare_runs.same(np.array(["ab", "c"], "<U2"), np.array(["ab", "c"], "<U7"))[0]  # text, not width
    assert compare_runs.same(np.array([1.0], np.float32), np.array([1.0], np.float64)) == (False, "dtype float32 vs float64")
    assert compare_runs.same(np.zeros(2), np.zeros(3)) == (False, "shape (2,) vs (3,)")
    assert not compare_runs.same(np.array([1, 2]), np.array([1, 3]))[0]


def test_a_copy_is_equal_in_every_stage(run_a, tmp_path, capsys):
    b = tmp_path / "b"
    shutil.copytree(run_a, b)
    assert compare_runs.main([str(run_a), str(b)]) == 0
    rows = compare_runs.compare_runs(run_a, b)
    assert {r["stage"] for r in rows} == set(compare_runs.STAGES)
    for r in rows:
        assert not r["differ"] and not r["only_old"] and not r["only_new"] and r["equal"], r["item"]
    by = _rows(rows)
    assert {"pca", "rhf", "unseen"} <= set(by[("features", "lift")]["equal"])
    assert {"acc", "loo", "correct"} <= set(by[("experiment", "pca/results.npz")]["equal"])
    with np.load(run_a / "results" / "pca" / "results.npz") as z:
        assert np.isnan(z["acc"]).any()  # NaN where a condition does not apply: compared equal
    assert "every compared key is equal" in capsys.readouterr().out


def test_a_changed_accuracy_finding_and_cell_are_named(run_a, tmp_path, capsys):
    b = tmp_path / "b"
    shutil.copytree(run_a, b)
    f = b / "results" / "rhf" / "results.npz"
    with np.load(f) as z:
        arrays = {k: z[k] for k in z.files}
    i = np.flatnonzero(np.isfinite(arrays["acc"]))[0]
    arrays["acc"].flat[i] += 0.25
    arrays["seconds"] = arrays["seconds"] + 1.0  # a wall time: not a result
    np.savez(f, **arrays)
    f = b / "report" / "findings.json"
    doc = json.loads(f.read_text())
    doc["findings"][1]["claims"][0]["estimate"] = 0.123
    f.write_text(json.dumps(doc))
    f = b / "report" / "affordances.csv"
    lines = f.read_text().splitlines()
    lines[1] = lines[1] + "x"
    f.write_text("\n".join(lines) + "\n")

    rows = compare_runs.compare_runs(run_a, b)
    by = _rows(rows)
    assert by[("experiment", "rhf/results.npz")]["differ"] == [("acc", f"1 of {arrays['acc'].size} differ, max |diff| 0.25")]
    assert by[("experiment", "pca/results.npz")]["differ"] == []
    fid = doc["findings"][1]["id"]
    assert [k for k, _ in by[("report", "findings.json")]["differ"]] == [f"{fid}.claims[0].estimate"]
    assert len(by[("report", "affordances.csv")]["differ"]) == 1
    assert compare_runs.first_difference(rows)["item"] == "rhf/results.npz"
    assert compare_runs.main([str(run_a), str(b)]) == 1
    assert "first difference: experiment (rhf/results.npz)" in capsys.readouterr().out


def test_features_differing_after_equal_rollouts(tmp_path):
    """Same rollouts, other features: the first difference is the features stage, and a field
    only one side stores is listed, not counted."""
    def made(name, scale, extra=False):
        p = tmp_path / name / "data" / "lift"
        standins.gen(p, n=24, batch=12)
        fn = standins.feature_fn()

        def compute(s):
            out = {k: v * scale if k == "pca" else v for k, v in fn(s).items()}
            return dict(out, n_points=np.full(len(s["label"]), 7, np.int32)) if extra else out

        ds.add_features(p, compute, batch=12, progress=False, config_dict={"voxel": 0.0125})
        return tmp_path / name

    a, b = made("a", 1.0), made("b", 2.0, extra=True)
    rows = _rows(compare_runs.compare_runs(a, b))
    assert rows[("generate", "lift")]["differ"] == [] and "label" in rows[("generate", "lift")]["equal"]
    assert [k for k, _ in rows[("features", "lift")]["differ"]] == ["pca"]
    assert sorted(rows[("features", "lift")]["equal"]) == ["rhf", "unseen"]
    assert rows[("features", "lift")]["only_new"] == ["n_points"] and rows[("features", "lift")]["only_old"] == []
    assert compare_runs.first_difference(list(rows.values()))["stage"] == "features"


def test_not_a_run_folder_is_one_line(tmp_path, capsys):
    assert compare_runs.main([str(tmp_path), str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("compare_runs: error:")


def test_a_damaged_dataset_is_one_line(run_a, tmp_path, capsys):
    b = tmp_path / "b"
    shutil.copytree(run_a, b)
    (b / "data" / "move" / "relaff_dataset.json").write_text("{not json")
    assert compare_runs.main([str(run_a), str(b)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("compare_runs: error:") and "relaff_dataset.json" in err[0]
