"""docs/extending.md: its two examples (examples/) run through `relaff experiment` from outside the
package, and the page shows them as they are."""
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from helpers import ROOT

EXAMPLES = ROOT / "examples"
SETS = ["--set", 'reproduce.actions=["lift","pull","take"]', "--set", "experiment.sizes=[2,4,10]",
        "--set", "experiment.reps_pca=2", "--set", "experiment.online_select=false"]


def _code_blocks(text: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


@pytest.mark.parametrize("name", ["centroid_learner.py", "vote_condition.py"])
def test_the_page_shows_each_example_as_it_is(name):
    assert (EXAMPLES / name).read_text() in _code_blocks((ROOT / "docs" / "extending.md").read_text(), "python")


def _relaff(args, tmp_path, env=None):
    return subprocess.run([sys.executable, "-m", "relaff_jax.cli", *args], cwd=tmp_path, capture_output=True,
                          text=True, env=dict(os.environ, **(env or {})))


def test_the_learner_example_runs_and_is_recorded(tmp_path):
    out = tmp_path / "centroid"
    run = _relaff(["experiment", "--synthetic", "200", "--out", str(out), "--space", "pca", "--jobs", "2",
                   "--no-progress", "--set", "experiment.learner=centroid_learner.CentroidClassifier",
                   "--set", 'experiment.learner_params={"shrink": 0.5}', *SETS], tmp_path,
                  env={"PYTHONPATH": str(EXAMPLES)})  # two worker processes import it by path
    assert run.returncode == 0, run.stderr
    cfg = json.loads((out / "experiment.json").read_text())["config"]
    assert cfg["learner"] == "centroid_learner.CentroidClassifier" and cfg["learner_params"] == {"shrink": 0.5}
    acc = np.load(out / "pca" / "results.npz")["acc"]
    assert np.isfinite(acc[:, 0]).all()
    # the centroid learner on the synthetic relations: above chance at n = 10 on average
    assert np.nanmean(acc[:, 0, -1]) > 0.55
    report = _relaff(["report", str(out), "--out", str(tmp_path / "report")], tmp_path)
    assert report.returncode == 0, report.stderr


def test_the_condition_example_runs_from_outside_the_package(tmp_path):
    out = tmp_path / "vote"
    run = _relaff(["experiment", "--synthetic", "200", "--out", str(out), "--space", "pca", "--jobs", "1",
                   "--no-progress", "--plugins", str(EXAMPLES / "vote_condition.py"),
                   "--set", 'experiment.conditions_pca=["NB","DB1","DBn","CB1","CBn","VOTE"]', *SETS], tmp_path)
    assert run.returncode == 0, run.stderr
    r = np.load(out / "pca" / "results.npz")
    names = list(r["conditions"])
    assert names[-2:] == ["VOTE:share", "VOTE:any"]
    assert np.isfinite(r["acc"][:, names.index("VOTE:share")]).all()
    assert "VOTE" in json.loads((out / "experiment.json").read_text())["plugins"]
