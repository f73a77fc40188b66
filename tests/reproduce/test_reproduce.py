"""`relaff reproduce`: stages, skip logic, --force, resume after an interruption, bad input.

The simulation and the perception are replaced by numpy stand-ins (rollouts and features drawn
from the rollout key / index), so these tests run the real dataset, experiment and report
stages in seconds; they check the driver, not any result. The end-to-end run with the arm's
actions is tests/e2e/test_reproduce_e2e.py. The stand-ins are tests/helpers/standins.py.
"""
import argparse
import dataclasses
import io
import json
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from relaff_jax import data as D
from relaff_jax import learn as E
from relaff_jax.learn.results import is_complete, load_results
from relaff_jax.config.experiment import experiment_preset
from relaff_jax import reproduce as R
from relaff_jax.config import PRESETS, preset
from relaff_jax import config as runconfig
from relaff_jax.cli import reproduce as cli_reproduce
from relaff_jax.config import override
from relaff_jax.constants import FAMILIES
from relaff_jax.errors import UserError
from relaff_jax.stages import features as stage_features
from relaff_jax.stages import generate as stage_generate
from relaff_jax.stages import report as stage_report

from helpers import TESTS, standins
from helpers.standins import HOOKS, feature_factory, rollout_factory

ACTS = ("lift", "take", "pour")
FAST = dict(standins.SMALL_RUN, **{"reproduce.actions": ACTS})


def run(out, seed=3, **kw):
    return standins.run(out, ACTS, seed, **kw)


def statuses(log):
    return {s: v["status"] for s, v in log["runs"][-1]["stages"].items()}


def results_of(out):
    res = load_results(out / "results")
    return {s: res[s]["acc"] for s in res["meta"]["spaces"]}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """One uninterrupted run through the CLI (factories patched in), then a second one."""
    out = tmp_path_factory.mktemp("run") / "quick"
    mp = pytest.MonkeyPatch()
    mp.setattr(stage_generate, "rollout_factory_for", lambda cfg: rollout_factory)
    mp.setattr(stage_features, "factories_for", lambda cfg: (feature_factory, HOOKS.feature_config))
    parser = argparse.ArgumentParser()
    cli_reproduce.register(parser.add_subparsers(dest="command"))
    sets = [x for k, v in FAST.items() for x in ("--set", f"{k}={json.dumps(v)}")]
    argv = ["reproduce", "--preset", "tiny", "--out", str(out), "--seed", "3", "--jobs", "1", "--no-progress"] + sets
    args = parser.parse_args(argv)
    buf = io.StringIO()
    mp.setattr(sys, "stdout", buf)
    assert args.func(args) == 0
    first = json.loads((out / R.RUN_LOG).read_text())
    second = run(out)
    mp.undo()
    return out, first, second, buf.getvalue()


def test_run_writes_every_expected_file(base):
    out, log, _, printed = base
    assert sorted(p.name for p in (out / "data").iterdir()) == sorted(ACTS)
    for a in ACTS:
        d = D.load_dataset(out / "data" / a)
        assert len(d["label"]) == 32
        assert d["label"].sum() == 16
        assert d["pca"].shape == (32, 18)
    res = load_results(out / "results")
    assert res["meta"]["actions"] == list(ACTS)
    assert res["meta"]["spaces"] == ["pca", "rhf"]
    assert res["pca"]["acc"].shape == (3, E.layout(3, 3)["n"], 2, 2)
    rep = out / "report"
    for f in ("report.md", "report.html", "findings.json", "summary.json", "table2.csv", "table2_rhf.csv",
              "fig_datasets.png", "fig06_nb_learning.png", "fig11_correlation.png", R.REPORT_STAMP):
        assert (rep / f).stat().st_size > 0, f
    assert statuses(log) == dict.fromkeys(R.STAGES, "ran")
    assert all(line.split()[0] in R.STAGES + ("total",) for line in printed.strip().splitlines())


def test_run_log(base):
    out, log, _, _ = base
    assert log["format"] == R.FORMAT
    assert log["preset"] == "tiny"
    assert log["seed"] == 3
    assert log["config"]["dataset"]["n_samples"] == 32
    assert log["config"]["experiment"]["forest"]["max_trees"] == 4
    assert runconfig.from_json(log["config"]) == override(preset("tiny"), {**FAST, "seed": 3})  # the tree records it
    assert log["versions"]["numpy"] == np.__version__
    assert log["versions"]["jax"]
    assert log["seeds"] == R.seeds(3)
    assert len(set(log["seeds"]["datasets"].values())) == 9  # every action its own stream
    for a in ACTS:
        s = log["seeds"]["datasets"][a]
        assert json.loads((out / "data" / a / D.SIDECAR).read_text())["seed"] == s
    assert set(log["timings"]) == set(R.STAGES)
    assert all(t > 0 for t in log["timings"].values())
    run0 = log["runs"][0]
    assert run0["status"] == "complete"
    assert run0["argv"][:6] == ["relaff", "reproduce", "--preset", "tiny", "--out", str(out)]
    assert run0["jobs"] == 1
    assert run0["stages"]["generate"]["actions"]["lift"]["rollouts"] >= 32
    assert run0["stages"]["experiment"]["was"] == "absent"  # a fresh folder, not a resumed one


def _flat(d, prefix=""):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _flat(v, f"{prefix}{k}.")
        else:
            yield prefix + k, v


def test_relaff_experiment_and_reproduce_record_the_same_config_and_results(base, tmp_path, capsys):
    """Both routes call ``stages.experiment.experiment_folder``: the same record shape, the same
    experiment node, the actions and spaces that ran, and the same bits from the same datasets,
    tree and seed."""
    from relaff_jax import cli
    from relaff_jax.config import to_dict
    from relaff_jax.provenance import CONFIG_RECORD

    out, log, _, _ = base
    rec = json.loads((out / "results" / CONFIG_RECORD).read_text())
    quick = dict(_flat(to_dict(experiment_preset("quick"))))
    sets = [x for k, v in _flat(log["config"]["experiment"]) if quick[k] != v
            for x in ("--set", f"experiment.{k}={json.dumps(v)}")]
    argv = ["experiment", "--data", *(str(out / "data" / a) for a in ACTS), "--out", str(tmp_path / "results"),
            "--seed", str(log["seeds"]["experiment"]), "--jobs", "1", "--no-progress", *sets]
    assert cli.main(argv) == 0, capsys.readouterr().err
    mine = json.loads((tmp_path / "results" / CONFIG_RECORD).read_text())
    assert sorted(mine) == sorted(rec)
    assert rec["command"] == "experiment"
    assert mine["command"] == rec["command"]
    assert mine["config"]["experiment"] == rec["config"]["experiment"]
    assert rec["config"]["reproduce"]["actions"] == list(ACTS)
    assert mine["config"]["reproduce"]["actions"] == list(ACTS)  # the actions that ran, not the nine
    assert mine["config"]["reproduce"]["spaces"] == rec["config"]["reproduce"]["spaces"]
    theirs, ours = results_of(out), results_of(tmp_path)
    for s in ("pca", "rhf"):
        np.testing.assert_array_equal(ours[s], theirs[s])
    # the dataset folders hold the record too, written by the stage functions both routes call
    for a in ACTS:
        drec = json.loads((out / "data" / a / CONFIG_RECORD).read_text())
        assert sorted(drec) == sorted(rec)
        assert drec["command"] == "features"  # the last stage that wrote the folder (generate, then features)
        assert drec["config"]["dataset"] == log["config"]["dataset"]


def test_relaff_report_and_reproduce_write_the_same_report(base, tmp_path, capsys):
    """Both routes call stages.report.report_folder: the same findings from the same results, the same record
    shape, a stamp the report status accepts; every file either writes is one that
    report/folder.py names."""
    from relaff_jax import cli
    from relaff_jax.learn import folder as LF
    from relaff_jax.provenance import CONFIG_RECORD
    from relaff_jax.report import folder as RF
    from relaff_jax.report.status import inputs_stamp, report_status

    out, log, _, _ = base
    mine, theirs = tmp_path / "rep", out / "report"
    assert cli.main(["report", str(out / "results"), "--out", str(mine)]) == 0, capsys.readouterr().err
    assert capsys.readouterr().out == f"report: {mine}\n"
    for f in RF.REQUIRED + (RF.STAMP, RF.FINDINGS, CONFIG_RECORD):
        assert (mine / f).is_file(), f
    assert json.loads((mine / RF.FINDINGS).read_text()) == json.loads((theirs / RF.FINDINGS).read_text())
    rec, theirs_rec = (json.loads((d / CONFIG_RECORD).read_text()) for d in (mine, theirs))
    assert sorted(rec) == sorted(theirs_rec)
    assert rec["command"] == "report"
    assert theirs_rec["command"] == "report"
    tree = runconfig.from_json(rec["config"])
    assert report_status(mine, stage_report.stamp(tree, out / "results")) == ("complete", "stamped with the current inputs")
    # reproduce's stamp is the one it wrote before stages.report.report_folder existed: old run folders stay complete
    cfg = runconfig.from_json(log["config"])
    old = [LF.meta(out / "results")] + [LF.results(out / "results", s) for s in cfg.reproduce.spaces]
    old += [out / "data" / a / f for a in ACTS for f in (D.SIDECAR, D.FEATURES_SIDECAR)]
    assert json.loads((theirs / RF.STAMP).read_text()) == inputs_stamp(old, {"examples_per_action": 0})
    named = {v for k, v in vars(RF).items() if k.isupper() and isinstance(v, str)} | {CONFIG_RECORD}
    for d in (mine, theirs):
        assert sorted({p.name for p in d.iterdir()} - named) == [], d


def test_second_run_skips_every_stage(base):
    out, first, second, _ = base
    assert statuses(second) == dict.fromkeys(R.STAGES, "skipped")
    assert len(second["runs"]) == 2
    assert second["timings"] == first["timings"]
    assert second["runs"][1]["stages"]["generate"]["why"] == "3 of 3 complete"


def test_forced_stage_with_identical_output_keeps_the_later_ones(base):
    out, *_ = base
    acc = results_of(out)
    log = run(out, force=("features",))
    # the features are recomputed, bit for bit the same: experiment and report see the same inputs
    assert statuses(log) == {"generate": "skipped", "features": "ran", "experiment": "skipped", "report": "skipped"}
    assert log["runs"][-1]["force"] == ["features"]
    # recomputed without reading the old chunks first: each action's record says it was forced
    assert {v["was"] for v in log["runs"][-1]["stages"]["features"]["actions"].values()} == {"forced"}
    for s, a in results_of(out).items():
        np.testing.assert_array_equal(a, acc[s])


KILL_SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    from helpers import standins
    standins.run(sys.argv[1], {acts!r})
""")


@pytest.mark.slow  # a subprocess run killed with SIGKILL
def test_interrupted_and_killed_run_continues_to_the_same_results(base, tmp_path):
    """Ctrl-C in the generate stage, then SIGKILL while the experiment writes its blocks:
    the third attempt finishes with the results of the uninterrupted run."""
    out0, *_ = base
    out = tmp_path / "run"
    mid = lambda a, b: rollout_factory(a, b, stop_after=1 if a == "take" else None)
    with pytest.raises(KeyboardInterrupt):
        run(out, hooks=dataclasses.replace(HOOKS, rollout_factory=mid))
    log = json.loads((out / R.RUN_LOG).read_text())
    assert log["runs"][0]["status"] == "interrupted (in generate)"
    assert D.load_dataset(out / "data" / "lift")
    assert not (out / "data" / "take" / D.SELECTION).exists()

    script = tmp_path / "go.py"
    script.write_text(KILL_SCRIPT.format(tests=str(TESTS), acts=ACTS))
    proc = subprocess.Popen([sys.executable, str(script), str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    blocks = out / "results" / "pca" / "blocks"
    t0 = time.time()
    while proc.poll() is None and time.time() - t0 < 240:
        if blocks.is_dir() and len(list(blocks.glob("*.npz"))) >= 1:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.02)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the run finished before it could be killed"
    assert not is_complete(out / "results")
    log = json.loads((out / R.RUN_LOG).read_text())
    gen = log["runs"][1]["stages"]["generate"]["actions"]
    assert gen["lift"]["status"] == "skipped"
    assert gen["take"]["status"] == "ran"
    assert log["runs"][1]["status"] == "running"  # a SIGKILL leaves no chance to write more

    log = run(out)
    assert log["runs"][1]["status"].startswith("killed")  # the next run says what happened to it
    assert statuses(log) == {"generate": "skipped", "features": "skipped", "experiment": "ran", "report": "ran"}
    for a in ACTS:
        np.testing.assert_array_equal(D.load_dataset(out / "data" / a)["pca"], D.load_dataset(out0 / "data" / a)["pca"])
    for s, a in results_of(out).items():
        np.testing.assert_array_equal(a, results_of(out0)[s])
    assert json.loads((out / "report" / "findings.json").read_text()) == \
        json.loads((out0 / "report" / "findings.json").read_text())


def test_stale_results_are_recomputed(base, tmp_path):
    """Results whose data fingerprint does not match the datasets are not 'complete'."""
    out0, *_ = base
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    meta_path = out / "results" / "experiment.json"
    meta = json.loads(meta_path.read_text())
    meta["fingerprint"]["pca"]["lift"] = "0" * 64  # as if lift's data had changed
    meta_path.write_text(json.dumps(meta))
    log = run(out)
    assert statuses(log) == {"generate": "skipped", "features": "skipped", "experiment": "ran", "report": "ran"}
    assert log["runs"][-1]["stages"]["experiment"]["was"] == "stale"
    for s, a in results_of(out).items():
        np.testing.assert_array_equal(a, results_of(out0)[s])


def test_another_forest_engine_resumes_the_same_run(base, tmp_path):
    """The forest engine changes no result: a finished run asked again with another engine
    skips every stage (results not stale) and its log records the change; another protocol
    setting is still refused."""
    out0, *_ = base
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    log = run(out, overrides=dict(FAST, **{"experiment.forest.engine": "compiled"}))
    assert set(statuses(log).values()) == {"skipped"}
    changed = log["speed_settings_changed"]
    assert [(c["key"], c["was"], c["now"]) for c in changed] == [("experiment.forest.engine", "fast", "compiled")]
    assert log["config"]["experiment"]["forest"]["engine"] == "compiled"
    with pytest.raises(R.ReproduceError, match="experiment.forest.max_depth"):
        run(out, overrides=dict(FAST, **{"experiment.forest.engine": "compiled", "experiment.forest.max_depth": 7}))


def test_a_run_resumed_on_another_machine_says_where(base, tmp_path, monkeypatch):
    """An invocation on the machine that began the run records nothing more; one on another
    machine (here: other BLAS kernels) records that machine in its own entry."""
    import relaff_jax.reproduce.run as reproduce_run

    out0, *_ = base
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    log = run(out)
    assert "machine" not in log["runs"][-1] and log["machine"]["blas"] is not None
    other = dict(log["machine"], blas=[{"internal_api": "openblas", "version": "0.3.30", "architecture": "SkylakeX"}])
    monkeypatch.setattr(reproduce_run, "machine", lambda: other)
    log = run(out)
    assert log["runs"][-1]["machine"] == other
    assert json.loads((out / R.RUN_LOG).read_text())["runs"][-1]["machine"] == other


def test_a_damaged_run_log_is_rebuilt_and_the_finished_stages_kept(base, tmp_path):
    """A run.json cut short: --status and a rerun refuse it with the repair, and --rebuild-log
    with the run's options starts a new log in which every finished stage is skipped."""
    out0, *_ = base
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    (out / R.RUN_LOG).write_text((out / R.RUN_LOG).read_text()[:100])
    with pytest.raises(R.ReproduceError, match="damaged.*--rebuild-log"):
        R.status(out)
    with pytest.raises(R.ReproduceError, match="damaged.*--rebuild-log"):
        run(out)
    log = run(out, rebuild_log=True)
    assert set(statuses(log).values()) == {"skipped"}
    assert "rebuilt" in log
    assert (out / (R.RUN_LOG + ".damaged")).exists()
    with pytest.raises(R.ReproduceError, match="intact"):
        run(out, rebuild_log=True)


def test_one_damaged_dataset_is_redone_alone(base, tmp_path):
    """A chunk of take's dataset removed: the rerun refuses with the targeted repair in its
    message; --redo-dataset take makes take again (bit-identical), keeps lift's and pour's
    datasets as they were; the remade dataset is bit-identical, so the experiment and the report
    (whose inputs did not change) are skipped."""
    out0, *_ = base
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    lift_chunks = sorted(p.name for p in (out / "data" / "lift" / "chunks").iterdir())
    lift_mtime = (out / "data" / "lift" / D.SIDECAR).stat().st_mtime_ns
    shutil.rmtree(sorted((out / "data" / "take" / "chunks").iterdir())[0])
    st = R.status(out)
    assert st["generate"].state == "corrupt"
    # the report's own stamp is intact, but it rests on the damaged dataset: not "complete"
    assert st["report"].state == "stale"
    assert "generate is not complete" in st["report"].why
    with pytest.raises(R.ReproduceError) as e:
        run(out)
    assert "--redo-dataset take" in str(e.value)
    assert "--force generate" in str(e.value)
    with pytest.raises(R.ReproduceError, match="redo-dataset takes an action of this study"):
        run(out, redo=("push",))  # not among ACTS
    with pytest.raises(R.ReproduceError, match="give one"):
        run(out, redo=("take",), force=("generate",))
    log = run(out, redo=("take",))
    assert statuses(log) == {"generate": "ran", "features": "ran", "experiment": "skipped", "report": "skipped"}
    gen = log["runs"][-1]["stages"]["generate"]["actions"]
    assert gen["lift"]["status"] == "skipped"
    assert gen["pour"]["status"] == "skipped"
    assert gen["take"]["status"] == "ran"
    assert log["runs"][-1]["redo"] == ["take"]
    assert sorted(p.name for p in (out / "data" / "lift" / "chunks").iterdir()) == lift_chunks
    assert (out / "data" / "lift" / D.SIDECAR).stat().st_mtime_ns == lift_mtime  # lift untouched
    new, old = D.load_dataset(out / "data" / "take"), D.load_dataset(out0 / "data" / "take")
    assert set(new) == set(old)
    for k in sorted(k for k, v in new.items() if isinstance(v, np.ndarray)):
        np.testing.assert_array_equal(new[k], old[k])
    for s, a in results_of(out).items():
        np.testing.assert_array_equal(a, results_of(out0)[s])


def test_a_dataset_of_another_selection_scheme_is_selected_again(base, tmp_path):
    """A dataset selected before ``dataset.unsettled`` existed (its sidecar's scheme without
    it reads as "keep"): not stale, the generate stage selects it again from its rollouts and
    the features follow. The stand-ins return no ``settled``, so the selection is the same
    and the experiment is skipped."""
    out0, *_ = base
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    side = out / "data" / "pour" / D.SIDECAR
    meta = json.loads(side.read_text())
    del meta["selection_scheme"]["unsettled"]
    side.write_text(json.dumps(meta))
    st = R.status(out)
    assert st["generate"].state == "partial" and "unsettled" in st["generate"].why
    log = run(out)
    assert statuses(log) == {"generate": "ran", "features": "ran", "experiment": "skipped", "report": "skipped"}
    gen = log["runs"][-1]["stages"]["generate"]["actions"]
    assert [gen[a]["status"] for a in ACTS] == ["skipped", "skipped", "ran"]
    assert json.loads(side.read_text())["selection_scheme"]["unsettled"] == "refuse"
    new, old = D.load_dataset(out / "data" / "pour"), D.load_dataset(out0 / "data" / "pour")
    for k in sorted(k for k, v in new.items() if isinstance(v, np.ndarray)):
        np.testing.assert_array_equal(new[k], old[k])


def test_a_second_run_in_the_same_folder_is_refused(base, tmp_path):
    """While one reproduce holds the folder, another is refused at once and writes nothing."""
    from relaff_jax import io as rio

    out0, *_ = base
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    before = (out / R.RUN_LOG).read_bytes()
    with rio.folder_lock(out, "held by this test"):
        with pytest.raises(UserError, match="another relaff reproduce is running in this folder"):
            run(out)
    assert (out / R.RUN_LOG).read_bytes() == before
    assert set(statuses(run(out)).values()) == {"skipped"}  # free again once the first is done


def test_a_corrupt_feature_chunk_is_reported_and_recomputed(base, tmp_path, monkeypatch):
    """One flipped byte in a feature chunk: the status names it, and both a plain rerun and
    --force features recompute it (the forced rerun used to fail on the same error)."""
    out0, *_ = base
    # R.status rebuilds the run from run.json: give it the stand-in perception
    monkeypatch.setattr(stage_features, "factories_for", lambda cfg: (feature_factory, HOOKS.feature_config))
    for force in ((), ("features",)):
        out = tmp_path / f"run{len(force)}"
        shutil.copytree(out0, out)
        for f in (out / "data" / "lift" / "features" / "chunk_000000" / "arrays").rglob("*"):
            if f.is_file() and f.parent.name == "d":
                b = bytearray(f.read_bytes())
                b[len(b) // 2] ^= 0xFF
                f.write_bytes(bytes(b))
        st = R.status(out)
        assert st["generate"].state == "complete"
        assert st["features"].state == "corrupt"
        assert "lift" in st["features"].why
        log = run(out, force=force)
        assert statuses(log)["features"] == "ran"
        np.testing.assert_array_equal(D.load_dataset(out / "data" / "lift")["pca"],
                                      D.load_dataset(out0 / "data" / "lift")["pca"])
        for s, a in results_of(out).items():
            np.testing.assert_array_equal(a, results_of(out0)[s])


def test_stage_progress_comes_from_the_stage_packages(base, tmp_path):
    from relaff_jax.learn.status import sweep_progress

    out, *_ = base
    cfg = override(preset("tiny"), FAST)
    assert D.generation_progress(out / "data" / "lift", 32) == 1.0
    assert D.features_progress(out / "data" / "lift", 32, cfg.dataset.feature_batch) == 1.0
    assert sweep_progress(out / "results", cfg.experiment, len(ACTS), ("pca", "rhf")) == 1.0
    assert D.generation_progress(tmp_path / "none", 32) == 0.0
    assert D.features_progress(tmp_path, 32, 8) == 0.0
    assert sweep_progress(tmp_path / "none", cfg.experiment, len(ACTS), ("pca",)) == 0.0


# ---------------------------------------------------------------------------- bad input


def test_bad_input(tmp_path):
    with pytest.raises(R.ReproduceError, match="unknown preset"):
        R.reproduce(tmp_path / "a", "fast")
    with pytest.raises(R.ReproduceError, match="--force takes a stage"):
        run(tmp_path / "a", force=("learn",))
    with pytest.raises(R.ReproduceError, match="jobs"):
        run(tmp_path / "a", jobs=-1)
    with pytest.raises(R.ReproduceError, match="seed"):
        run(tmp_path / "a", seed=-1)
    with pytest.raises(UserError, match="unknown config key 'n_sample'"):
        run(tmp_path / "a", overrides={"n_sample": 10})
    with pytest.raises(UserError, match="unknown config key 'dataset.n_sample'"):
        run(tmp_path / "a", overrides={"dataset.n_sample": 10})
    with pytest.raises(UserError, match="expects an integer"):
        run(tmp_path / "a", overrides={"dataset.n_samples": "many"})
    # the experiment's pools must fit: fail before simulating anything
    with pytest.raises(R.ReproduceError, match="cannot run on 20 samples"):
        run(tmp_path / "a", overrides=dict(FAST, **{"dataset.n_samples": 20}))
    # a bad value is refused by its config node when the tree is built, before any work
    with pytest.raises(UserError, match="'reproduce.actions' must be in the run's order"):
        run(tmp_path / "a", overrides=dict(FAST, **{"reproduce.actions": ("take", "lift")}))
    with pytest.raises(UserError, match="'reproduce.actions' must be a list of at least 2 values"):
        run(tmp_path / "a", overrides=dict(FAST, **{"reproduce.actions": ("lift",)}))
    with pytest.raises(UserError, match="'dataset.rollout_batch' must be an integer in \\[1, "):
        run(tmp_path / "a", overrides=dict(FAST, **{"dataset.rollout_batch": 0}))
    # a perception value is refused before generation, not when the features stage reaches it
    with pytest.raises(UserError, match=r"'perception.voxel.size' must be a finite number in \(0.0, 1.0\]"):
        run(tmp_path / "a", overrides=dict(FAST, **{"perception.voxel.size": -1.0}))
    assert not (tmp_path / "a").exists()
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(R.ReproduceError, match="not a relaff reproduce folder"):
        run(foreign)
    with pytest.raises(R.ReproduceError, match="needs feature_config"):
        R.Hooks(feature_factory=feature_factory)


def test_other_seed_or_preset_in_the_same_folder_is_refused(base):
    out, *_ = base
    with pytest.raises(R.ReproduceError, match="another seed"):
        run(out, seed=4)
    with pytest.raises(R.ReproduceError, match="another config"):
        run(out, overrides=dict(FAST, **{"dataset.n_samples": 40}))


def test_missing_actions_module_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "relaff_jax.sim.rollouts", None)  # as if the module did not exist
    parser = argparse.ArgumentParser()
    cli_reproduce.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["reproduce", "--preset", "tiny", "--out", str(tmp_path / "r"), "--no-progress"]
                             + [x for k, v in FAST.items() for x in ("--set", f"{k}={json.dumps(v)}")])
    with pytest.raises(R.ReproduceError, match="needs relaff_jax.sim.rollouts"):
        args.func(args)
    log = json.loads((tmp_path / "r" / R.RUN_LOG).read_text())
    assert log["runs"][0]["status"].startswith("failed: ReproduceError")
    assert "(in generate)" in log["runs"][0]["status"]


def test_presets():
    tiny, quick, study, paper = (preset(p) for p in PRESETS)
    for p in (tiny, quick, study, paper):
        R.check_config(p, 0)
    assert paper.dataset.n_samples == 10_000
    assert paper.experiment == experiment_preset("paper")
    assert (paper.experiment.reps_pca, paper.experiment.reps_rhf) == (50, 25)
    assert tiny.experiment.reps_pca == 2
    assert set(range(4, 11)) <= set(tiny.experiment.sizes)
    assert tiny.dataset.n_samples < 100
    assert quick.experiment.conditions_pca == FAMILIES  # every bootstrapping condition
    assert quick.reproduce.spaces == ("pca", "rhf")


def test_a_killed_run_is_marked_and_its_stage_time_counted(tmp_path, monkeypatch):
    """SIGKILL leaves ``running`` in the log; the heartbeat file says how long the stage had
    run, and the next invocation marks the run ``killed`` and adds that time to the timings."""
    from relaff_jax.reproduce import run as RR

    out = tmp_path / "run"
    first = run(out)
    paths = R.Paths(out)
    log = json.loads(paths.log.read_text())
    before = log["timings"]["experiment"]
    log["runs"].append({"status": "running", "stages": {}, "started": "x"})  # as SIGKILL leaves it
    paths.log.write_text(json.dumps(log))
    (out / RR.HEARTBEAT).write_text(json.dumps({"stage": "experiment", "seconds": 12.5, "run_seconds": 20.0,
                                                 "at": "2026-12-05 17:00:00"}))
    log = run(out)
    killed = log["runs"][-2]
    assert killed["status"] == "killed (in experiment)"
    assert killed["stages"]["experiment"] == {"status": "killed", "seconds": 12.5, "counted_until": "2026-12-05 17:00:00"}
    assert log["timings"]["experiment"] == pytest.approx(before + 12.5)
    assert not (out / RR.HEARTBEAT).exists() and first["runs"][-1]["status"] == "complete"


def test_the_heartbeat_records_the_running_stage(tmp_path, monkeypatch):
    from relaff_jax.reproduce import run as RR

    monkeypatch.setattr(RR, "HEARTBEAT_SECONDS", 0.05)
    (tmp_path / "r").mkdir()
    beat = RR._Heartbeat(R.Paths(tmp_path / "r"), lambda: ("features", 3.0, 7.0))
    t0 = time.time()
    while not (tmp_path / "r" / RR.HEARTBEAT).exists() and time.time() - t0 < 10:
        time.sleep(0.02)
    got = json.loads((tmp_path / "r" / RR.HEARTBEAT).read_text())
    beat.stop()
    assert (got["stage"], got["seconds"], got["run_seconds"]) == ("features", 3.0, 7.0)
    assert not (tmp_path / "r" / RR.HEARTBEAT).exists()  # a finished invocation's log has the exact figures


TERM_SCRIPT = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, {tests!r})
    from helpers import standins as T
    from relaff_jax import cli
    from relaff_jax.stages import features, generate
    slow = lambda a, b: (lambda fn: (lambda k, n: (__import__("time").sleep(0.5), fn(k, n))[1]))(T.rollout_factory(a, b)[0])
    generate.rollout_factory_for = lambda cfg: (lambda a, b: (slow(a, b), {{"stand_in": a}}, None))
    features.factories_for = lambda cfg: (T.feature_factory, T.HOOKS.feature_config)
    fast = dict(T.SMALL_RUN, **{{"reproduce.actions": {acts!r}}})
    sets = [x for k, v in fast.items() for x in ("--set", f"{{k}}={{json.dumps(v)}}")]
    sys.exit(cli.main(["reproduce", "--preset", "tiny", "--out", sys.argv[1], "--seed", "3", "--jobs", "1",
                       "--no-progress"] + sets))
""")


@pytest.mark.slow  # a subprocess run stopped with SIGTERM
def test_sigterm_is_one_line_and_the_run_log_says_terminated(tmp_path):
    out = tmp_path / "run"
    script = tmp_path / "go.py"
    script.write_text(TERM_SCRIPT.format(tests=str(TESTS), acts=ACTS))
    proc = subprocess.Popen([sys.executable, str(script), str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    t0 = time.time()
    while time.time() - t0 < 240 and not (out / "data" / "lift").is_dir():
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("relaff reproduce: terminated (SIGTERM)"), err
    log = json.loads((out / R.RUN_LOG).read_text())
    assert log["runs"][-1]["status"] == "terminated (SIGTERM) (in generate)"
    assert log["timings"]["generate"] >= 0  # the killed part of the stage is recorded (it may round to 0.0 s)
