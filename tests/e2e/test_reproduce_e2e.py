"""End to end: `relaff reproduce --preset tiny` with the arm's nine actions (scenes settled in
MJX, motor programs run by MuJoCo C: ``--engine native``, the engine of the quick and paper
presets; the MJX executor of every action is tested in tests/sim/test_actions.py), the Kinect
perception, the forests and the report.

Checks every expected file, that a second run skips every stage, and that a run interrupted
in the middle of simulating a dataset, then rerun, ends with the dataset of the uninterrupted
run: the same arrays, so the same labels-and-features fingerprint, so its experiment is
skipped as up to date, and the report made again (its stamp covers the datasets' files, whose
audit records its own seconds) has the same findings (the interruption is a KeyboardInterrupt
raised after the first chunk, in process, so that the compiled programs are reused; that a
rerun experiment gives the same results: tests/reproduce/test_reproduce.py, which SIGKILLs a
run of numpy stand-ins). Then two datasets made again with each audit on its background
thread beside the next generation and the report's example scenes drawn in a second process
(what a machine of two cores or more runs; a test worker has one core): the same datasets,
audits, pictures and findings.
Slow: it simulates every action (docs/reproduce.md).
"""
import argparse
import json
import shutil

import numpy as np
import pytest

from relaff_jax import data as D
from relaff_jax import learn as E
from relaff_jax.learn.results import is_complete, load_results
from relaff_jax.data.status import manifest_fingerprint
from relaff_jax import reproduce as R
from relaff_jax.config import preset
from relaff_jax.cli import reproduce as cli_reproduce
from relaff_jax.stages.generate import default_rollout_factory
from relaff_jax.stages import audits
from relaff_jax.report import examples
from relaff_jax.data.audit import AUDIT_FILE

pytestmark = [pytest.mark.slow, pytest.mark.timeout(5400)]

SEED = 5


def cli_run(out, *extra):
    parser = argparse.ArgumentParser()
    cli_reproduce.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["reproduce", "--preset", "tiny", "--out", str(out), "--seed", str(SEED),
                              "--engine", "native", "--no-progress", *extra])
    assert args.func(args) == 0
    return json.loads((out / R.RUN_LOG).read_text())


def statuses(log):
    return {s: v["status"] for s, v in log["runs"][-1]["stages"].items()}


def test_tiny_end_to_end(tmp_path, monkeypatch):
    out = tmp_path / "tiny"
    log = cli_run(out)
    cfg = preset("tiny")
    assert statuses(log) == dict.fromkeys(R.STAGES, "ran")

    # every expected file
    for a in R.ACTIONS:
        d = D.load_dataset(out / "data" / a)
        n = cfg.dataset.n_samples
        assert d["label"].shape == (n,)
        assert d["label"].sum() == n // 2
        assert d["pca"].shape == (n, 18)
        assert d["rhf"].shape == (n, 300)
        assert np.isfinite(d["pca"]).all()
        assert d["qpos_settled"].shape == (n, 14)
        info = D.info(out / "data" / a)
        assert info["status"] == "complete"
        assert info["features"]["status"] == "complete"
    assert is_complete(out / "results", R.SPACES)
    res = load_results(out / "results")
    assert res["meta"]["actions"] == list(R.ACTIONS)
    assert res["pca"]["acc"].shape == (9, E.layout(9, 3)["n"], len(cfg.experiment.sizes), 2)
    rep = out / "report"
    for f in ("report.md", "report.html", "findings.json", "summary.json", "table2.csv", "table2_rhf.csv",
              "table2.md", "fig_datasets.png", "fig06_nb_learning.png", "fig07_nb_spaces.png",
              "fig08_db1_best.png", "fig09_db1_best_bf.png", "fig10_average_bf.png", "fig11_correlation.png",
              "fig12_thresholds.png", R.REPORT_STAMP):
        assert (rep / f).stat().st_size > 0, f
    assert len(list((rep / "examples").glob("*.png"))) == 9 * cfg.reproduce.examples_per_action
    md = (rep / "report.md").read_text()
    for a in R.ACTIONS:
        assert f"| {a} | {cfg.dataset.n_samples} |" in md
    assert len(json.loads((rep / "findings.json").read_text())["findings"]) == 5
    assert set(log["timings"]) == set(R.STAGES)

    # a second run skips every stage
    log = cli_run(out)
    assert statuses(log) == dict.fromkeys(R.STAGES, "skipped")

    # interrupted after the first chunk of take (the cheapest action to regenerate), then rerun:
    # the same dataset, so the results made from the first are up to date
    out2 = tmp_path / "interrupted"
    shutil.copytree(out, out2)
    shutil.rmtree(out2 / "data" / "take")

    def stop_after_first_chunk(action, batch):
        fn, config, names = default_rollout_factory(action, batch, engine="native")
        calls = [0]

        def rollout(key, b):
            calls[0] += 1
            if calls[0] > 1:
                raise KeyboardInterrupt
            return fn(key, b)

        return rollout, config, names

    with pytest.raises(KeyboardInterrupt):
        R.reproduce(out2, "tiny", SEED, progress=False, overrides={"dataset.engine": "native"},
                    hooks=R.Hooks(rollout_factory=stop_after_first_chunk))
    assert len(list((out2 / "data" / "take" / D.CHUNKS).iterdir())) == 1
    log = cli_run(out2)
    assert statuses(log) == {"generate": "ran", "features": "ran", "experiment": "skipped", "report": "ran"}
    gen = log["runs"][-1]["stages"]["generate"]["actions"]
    assert gen["take"]["status"] == "ran"
    assert gen["lift"]["status"] == "skipped"
    a, b = D.load_dataset(out / "data" / "take"), D.load_dataset(out2 / "data" / "take")
    for k in ("rollout", "label", "qpos_settled", "pca", "rhf"):
        np.testing.assert_array_equal(a[k], b[k])
    fp = manifest_fingerprint(out2 / "data" / "take")
    assert fp is not None and fp == manifest_fingerprint(out / "data" / "take")
    assert json.loads((out / "report" / "findings.json").read_text()) == \
        json.loads((out2 / "report" / "findings.json").read_text())

    # the audits beside the generation and the example scenes in their own process (two cores)
    out3 = tmp_path / "beside"
    shutil.copytree(out, out3)
    for a in ("move", "take"):
        shutil.rmtree(out3 / "data" / a)
    monkeypatch.setattr(audits, "MIN_CORES", 1)
    monkeypatch.setattr(examples, "MIN_CORES", 1)
    log = cli_run(out3)
    assert statuses(log) == {"generate": "ran", "features": "ran", "experiment": "skipped", "report": "ran"}
    gen = log["runs"][-1]["stages"]["generate"]["actions"]
    assert {a for a, v in gen.items() if v["status"] == "ran"} == {"move", "take"}
    for a in ("move", "take"):
        assert gen[a]["audit"]["label_agreement"] == 1.0
        x, y = (json.loads((o / "data" / a / AUDIT_FILE).read_text()) for o in (out, out3))
        for k in ("seconds", "dataset"):
            x.pop(k), y.pop(k)
        assert x == y
        assert manifest_fingerprint(out3 / "data" / a) == manifest_fingerprint(out / "data" / a)
    pics = sorted(p.name for p in (out / "report" / "examples").glob("*.png"))
    assert pics == sorted(p.name for p in (out3 / "report" / "examples").glob("*.png"))
    for name in pics:
        assert (out / "report" / "examples" / name).read_bytes() == (out3 / "report" / "examples" / name).read_bytes()
    assert json.loads((out / "report" / "findings.json").read_text()) == \
        json.loads((out3 / "report" / "findings.json").read_text())
