"""What a new user trips over: every path and every input-only condition is
checked before any work, with the one-line ``relaff CMD: error: ...`` and exit code 2.

The work itself is replaced by a function that fails the test if it is reached, so each test
takes well under a second and shows that the check comes first."""
from __future__ import annotations

import shutil

import pytest

from relaff_jax import cli

from helpers import OSD, TESTS



def no_work(*args, **kwargs):
    raise AssertionError("the work started before the inputs were checked")


def one_line_error(capsys, command: str) -> str:
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"relaff {command}: error: "), err
    return lines[0]


@pytest.fixture
def a_file(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("not a folder")
    return f


def test_real_segment_unwritable_out_fails_before_segmenting(monkeypatch, capsys, a_file):
    import relaff_jax.real.stages

    monkeypatch.setattr(relaff_jax.real.stages, "score_scenes", no_work)
    assert cli.main(["real", "segment", str(OSD), "--out", f"{a_file}/iou.json"]) == 2
    assert "is a file" in one_line_error(capsys, "real segment")


def test_real_show_unwritable_out_fails_before_reading(monkeypatch, capsys, a_file):
    import relaff_jax.real.stages

    monkeypatch.setattr(relaff_jax.real.stages, "read_cloud", no_work)
    assert cli.main(["real", "show", str(OSD / "learn0.pcd"), "--out", f"{a_file}/scene.png"]) == 2
    one_line_error(capsys, "real show")
    assert cli.main(["real", "show", str(OSD / "learn0.pcd"), "--out", str(a_file.parent)]) == 2
    assert "is a folder" in one_line_error(capsys, "real show")


@pytest.mark.parametrize("where", ["--out", "--pictures"])
def test_real_propose_unwritable_out_or_pictures_fails_before_proposing(monkeypatch, capsys, tmp_path, a_file,
                                                                        where):
    import relaff_jax.real.stages

    monkeypatch.setattr(relaff_jax.real.stages, "propose_folder", no_work)
    out = f"{a_file}/labels.csv" if where == "--out" else str(tmp_path / "labels.csv")
    argv = ["real", "propose", str(OSD), "--out", out]
    if where == "--pictures":
        argv += ["--pictures", str(a_file)]
    assert cli.main(argv) == 2
    assert where in one_line_error(capsys, "real propose")


def _labels(tmp_path, relations):
    """A labels file over the two shipped scenes' pairs with the given relations, checksums right."""
    from relaff_jax.real import labels as lab

    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copy(OSD / "learn0.pcd", scenes / "learn0.pcd")
    sha = lab.file_sha256(scenes / "learn0.pcd")
    rows = [lab.Label("learn0.pcd", 2, 3, r, sha) for r in relations]
    path = tmp_path / "labels.csv"
    path.write_text("scene,object_a,object_b,relation,sha256\n" +
                    "".join(f"{x.scene},{2 + i},{3 + i},{x.relation},{x.sha256}\n" for i, x in enumerate(rows)))
    return scenes, path


def test_real_study_checks_the_labels_before_any_work(monkeypatch, capsys, tmp_path):
    from relaff_jax.real import real_data

    monkeypatch.setattr(real_data, "cached_real_features", no_work)
    scenes, labels = _labels(tmp_path, ["beside", "beside", "on_top"])
    argv = ["real", "study", str(scenes), "--labels", str(labels), "--out", str(tmp_path / "study")]
    assert cli.main(argv) == 2
    line = one_line_error(capsys, "real study")
    assert ">= 2 pairs of each relation" in line
    assert "1 on_top" in line
    assert not (tmp_path / "study").exists()


def test_real_study_checks_the_simulation_budget_before_any_work(monkeypatch, capsys, tmp_path):
    from relaff_jax.real import labels as lab
    from relaff_jax.real import real_data

    monkeypatch.setattr(real_data, "cached_real_features", no_work)
    monkeypatch.setattr(lab, "validate", lambda labels, *a: labels)  # the scenes' object ids are not the point
    scenes, labels = _labels(tmp_path, ["beside", "beside", "on_top", "on_top"])
    argv = ["real", "study", str(scenes), "--labels", str(labels), "--out", str(tmp_path / "study"),
            "--per-relation", "10", "--n-full", "100"]
    assert cli.main(argv) == 2
    assert "SIM_full needs 100 simulated scenes of each relation" in one_line_error(capsys, "real study")


def test_export_uses_the_one_writability_check(monkeypatch, capsys, tmp_path):
    from relaff_jax import io as rio
    from relaff_jax.errors import UserError

    def refuse(path, what="--out"):
        raise UserError(f"{what} {path}: cannot write in it (probe)")

    monkeypatch.setattr(rio, "check_writable_dir", refuse)
    assert cli.main(["export", str(tmp_path), "--out", str(tmp_path / "x.parquet")]) == 2
    assert "(probe)" in one_line_error(capsys, "export")


def _run_folder(tmp_path):
    """A run folder holding only the run log of the tiny preset, seed 0 (no stage ran)."""
    from relaff_jax.reproduce.folder import Paths, open_log
    from relaff_jax.config import preset

    out = tmp_path / "run"
    open_log(Paths(out), "tiny", preset("tiny"), 0)
    return out


def test_reproduce_status_with_a_damaged_run_log_says_how_to_rebuild_it(capsys, tmp_path):
    out = _run_folder(tmp_path)
    (out / "run.json").write_text('{"format": "relaff_jax.reproduce", "conf')  # cut short by a full disk
    for argv in (["reproduce", "--status", "--out", str(out)], ["reproduce", "--status", str(out)]):
        assert cli.main(argv) == 2
        line = one_line_error(capsys, "reproduce")
        assert "run.json is damaged" in line
        assert "--rebuild-log" in line
        assert "use a new --out" not in line
    assert cli.main(["reproduce", "--preset", "tiny", "--out", str(out)]) == 2  # a run says the same
    assert "--rebuild-log" in one_line_error(capsys, "reproduce")


def test_reproduce_status_takes_the_folder_as_a_positional_argument(capsys, tmp_path):
    out = _run_folder(tmp_path)
    assert cli.main(["reproduce", "--status", str(out)]) == 0
    text = capsys.readouterr().out
    assert "\ngenerate " in text and "invocation(s)" in text.splitlines()[0]  # the run log's figures first
    assert cli.main(["reproduce", str(out)]) == 2
    assert f"--out {out}" in one_line_error(capsys, "reproduce")


def test_resuming_with_other_settings_names_only_the_keys_that_differ(capsys, tmp_path):
    out = _run_folder(tmp_path)
    argv = ["reproduce", "--preset", "tiny", "--out", str(out), "--set", "dataset.borrow_fraction=0.25"]
    assert cli.main(argv) == 2
    line = one_line_error(capsys, "reproduce")
    assert "1 key(s) differ: dataset.borrow_fraction: stored" in line
    assert "requested 0.25" in line
    assert "perception" not in line
    assert "experiment" not in line  # not the whole stored tree


PROBE = """
import sys
from relaff_jax import cli
code = cli.main(sys.argv[1:])
print(code, sorted(m for m in ("jax", "mujoco", "sklearn") if m in sys.modules))
"""


@pytest.mark.parametrize("argv", [
    ["generate", "lift", "--samples", "10", "--out", "{tmp}/d", "--set", "foo=1"],
    ["generate", "lift", "--samples", "10", "--out", "{tmp}/d", "--set", "dataset.n_sample=10"],
    ["reproduce", "--preset", "tiny", "--out", "{tmp}/r", "--set", "dataset.n_samples=many"],
    ["experiment", "--synthetic", "10", "--out", "{tmp}/e", "--set", "foo=1"],
    ["scenes", "3", "--set", "foo=1"],
    ["features", "{tmp}", "--set", "foo=1"],
    ["features", "{tmp}", "--set", "perception.voxel.sise=0.02"],
    # the simulation's and the learning's nodes load without JAX, MJX and scikit-learn too
    ["generate", "lift", "--samples", "10", "--out", "{tmp}/d", "--set", "action.lift_hieght=0.3"],
    ["reproduce", "--preset", "tiny", "--out", "{tmp}/r", "--set", "action.scene.p_stacked=abc"],
    ["experiment", "--synthetic", "10", "--out", "{tmp}/e", "--set", "experiment.forest.max_trees=many"],
    ["show", "{tmp}", "--set", "action.arm.ik_step=3"],
])
def test_a_config_mistake_is_reported_before_jax_is_imported(tmp_path, argv):
    import subprocess
    import sys

    argv = [a.format(tmp=tmp_path) for a in argv]
    r = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, timeout=120)
    assert r.stdout == "2 []\n", (r.stdout, r.stderr)  # exit code 2, and no JAX, MuJoCo or sklearn loaded
    assert r.stderr.startswith(f"relaff {argv[0]}: error: ")
    assert "config key" in r.stderr
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("argv", [
    ["features", "{tmp}/none"],
    ["show", "{tmp}/none"],
    ["experiment", "--data", "{tmp}/none", "--out", "{tmp}/e"],
    ["experiment", "--synthetic", "10", "--out", "{tmp}/e", "--reuse", "{tmp}/none"],
    ["report", "{tmp}/none", "--out", "{tmp}/r"],
    ["real", "segment", "{tmp}/none"],
    ["real", "show", "{tmp}/none.pcd"],
    ["real", "study", "{tmp}/none", "--labels", "{tmp}/l.csv", "--out", "{tmp}/s"],
])
def test_a_missing_input_is_reported_before_the_stage_is_imported(tmp_path, argv):
    import subprocess
    import sys

    argv = [a.format(tmp=tmp_path) for a in argv]
    r = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, timeout=120)
    assert r.stdout == "2 []\n", (r.stdout, r.stderr)
    command = " ".join(argv[:2]) if argv[0] == "real" else argv[0]
    assert r.stderr.startswith(f"relaff {command}: error: "), r.stderr
    assert str(tmp_path) in r.stderr, r.stderr
    assert not any(tmp_path.iterdir())


def test_generate_refuses_a_sample_count_beyond_the_rollout_cap_with_the_projected_time(monkeypatch, capsys,
                                                                                          tmp_path):
    import relaff_jax.sim.rollouts
    from relaff_jax import data

    monkeypatch.setattr(relaff_jax.sim.rollouts, "make_rollout_fn", no_work)
    monkeypatch.setattr(data, "generate_dataset", no_work)
    argv = ["generate", "lift", "--samples", "1000000000000", "--out", str(tmp_path / "d")]
    assert cli.main(argv) == 2
    line = one_line_error(capsys, "generate")
    assert "needs at least N rollouts" in line
    assert "caps them at 200,192" in line  # 200,000 in chunks of 256
    assert "years at ~5 rollouts/s" in line
    assert cli.main(argv[:3] + ["300", "--max-rollouts", "256", "--batch", "64", "--engine", "native",
                                "--out", str(tmp_path / "d")]) == 2
    assert "--samples 300 cannot be reached" in one_line_error(capsys, "generate")
    assert not (tmp_path / "d").exists()


def test_reproduce_refuses_a_sample_count_beyond_the_rollout_cap(monkeypatch, capsys, tmp_path):
    from relaff_jax.stages import generate as stage_generate

    monkeypatch.setattr(stage_generate, "rollout_factory_for", lambda cfg: no_work)
    argv = ["reproduce", "--preset", "tiny", "--out", str(tmp_path / "r"), "--set", "dataset.n_samples=5000"]
    assert cli.main(argv) == 2
    line = one_line_error(capsys, "reproduce")
    assert "dataset.n_samples 5,000 cannot be reached" in line
    assert "dataset.max_rollouts caps them at 2,000" in line
    assert not (tmp_path / "r").exists()


def test_no_test_prints_past_the_capture():
    """`pytest -q` output is the dots and the summary: a test's figures go in its assertion
    messages or in captured prints (shown with a failure), never past the capture."""
    here = TESTS
    bypass = "capsys" + ".disabled("
    offenders = [p.name for p in sorted(here.rglob("test_*.py")) if bypass in p.read_text()]
    assert offenders == []


def test_compare_unwritable_out_fails_before_reading_the_reports(monkeypatch, capsys, tmp_path, a_file):
    import relaff_jax.report.readings

    monkeypatch.setattr(relaff_jax.report.readings, "compare_readings", no_work)
    argv = ["compare", f"a={tmp_path}/a", f"b={tmp_path}/b", "--out", f"{a_file}/page.md"]
    assert cli.main(argv) == 2
    assert "is a file" in one_line_error(capsys, "compare")


def test_generate_help_prints_a_plain_percent(capsys):
    with pytest.raises(SystemExit):
        cli.main(["generate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "50% positives" in out
    assert "%%" not in out
    assert "--engine native" in out


def test_a_run_begun_before_a_setting_existed_resumes_at_its_default(tmp_path):
    """A config key missing from run.json (added to the code later) is the same run when it is
    requested at its default, and a refused one otherwise."""
    import json as _json

    from relaff_jax.config import override
    from relaff_jax.reproduce.folder import Paths, ReproduceError, open_log
    from relaff_jax.config import preset

    out = _run_folder(tmp_path)
    log = _json.loads((out / "run.json").read_text())
    del log["config"]["experiment"]["state"], log["config"]["dataset"]["population"]
    (out / "run.json").write_text(_json.dumps(log))
    with pytest.raises(ReproduceError, match="dataset.population: stored \"<absent>\", requested \"feasible\""):
        open_log(Paths(out), "tiny", override(preset("tiny"), {"dataset.population": "feasible"}), 0)
    back = open_log(Paths(out), "tiny", preset("tiny"), 0)
    assert sorted(back["added_settings"]) == ["dataset.population", "experiment.state"]
    assert "population" in _json.loads((out / "run.json").read_text())["config"]["dataset"]


@pytest.mark.parametrize("argv,flag", [
    (["generate", "lift", "--samples", "100", "--out", "{tmp}/d", "--set", "dataset.n_samples=50"], "--samples 100"),
    (["generate", "lift", "--samples", "10", "--batch", "8", "--out", "{tmp}/d", "--set", "dataset.rollout_batch=16"],
     "--batch 8"),
    (["features", "{tmp}", "--batch", "4", "--set", "dataset.feature_batch=8"], "--batch 4"),
    (["reproduce", "--preset", "tiny", "--out", "{tmp}/r", "--engine", "native", "--set", "dataset.engine=mjx"],
     "--engine native"),
])
def test_a_flag_and_a_set_of_its_key_that_disagree_are_refused(capsys, tmp_path, argv, flag):
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert cli.main(argv) == 2
    line = one_line_error(capsys, argv[0])
    assert flag in line
    assert "disagree" in line
    assert not any(tmp_path.iterdir())  # refused before anything is written
