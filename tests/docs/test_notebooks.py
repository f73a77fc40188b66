"""The notebooks run top to bottom (nbclient) on a small run folder, so they cannot rot.

Notebooks 02 and 03 read the session's ``scene_run`` folder (tests/helpers/fixtures.py): real settled scenes
with features under data/, and results/ from `relaff experiment --synthetic`. Notebook 01
builds its own two scenes and runs the lift action on them.
"""
from pathlib import Path

import nbclient
import nbformat
import pytest

from helpers import ROOT

NOTEBOOKS = ROOT / "notebooks"


def execute(name: str, run_dir: Path, monkeypatch) -> nbformat.NotebookNode:
    monkeypatch.setenv("RELAFF_RUN", str(run_dir))
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(NOTEBOOKS)}}).execute()
    return nb


def outputs(nb) -> str:
    text = []
    for cell in nb.cells:
        for o in cell.get("outputs", []):
            text.append(o.get("text", ""))
            if o.get("output_type") == "error":
                text.append("\n".join(o.get("traceback", [])))
    return "\n".join(text)


def images(nb) -> int:
    return sum("image/png" in o.get("data", {}) for c in nb.cells for o in c.get("outputs", []))


def test_notebooks_use_only_the_public_api():
    for path in sorted(NOTEBOOKS.glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        src = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
        assert "._" not in src.replace("__", ""), f"{path.name} uses a private name"
        assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), f"{path.name} is stored with outputs"


@pytest.mark.slow  # runs a notebook kernel on a simulated run
def test_02_features(scene_run, monkeypatch):
    nb = execute("02_features.ipynb", scene_run, monkeypatch)
    text = outputs(nb)
    assert "2 featured datasets" in text
    for rel in ("beside", "on_top"):
        assert f"\n{rel:<7} " in text  # an example of the relation was found and shown
    assert images(nb) >= 4  # scenes, PCA bars, two RHF grids


@pytest.mark.slow  # runs a notebook kernel on a simulated run
def test_03_learning_and_bootstrapping(scene_run, monkeypatch):
    nb = execute("03_learning_and_bootstrapping.ipynb", scene_run, monkeypatch)
    text = outputs(nb)
    assert "Table II (PCA) -- recomputed here, equal to experiment.analyse" in text
    assert "Table II (RHF)" in text
    assert images(nb) >= 3


@pytest.mark.slow  # compiles the settle and the action programs in a fresh kernel: minutes
def test_01_scenes_and_actions(monkeypatch, tmp_path):
    # 8 scenes: the batch shape of tests/sim/test_actions.py, whose programs the kernel loads
    # from the session's compilation cache (conftest.py) instead of compiling them again (in the
    # whole suite that file runs first: helpers/workers.py)
    monkeypatch.setenv("RELAFF_NB_SCENES", "8")
    nb = execute("01_scenes_and_actions.ipynb", tmp_path, monkeypatch)
    text = outputs(nb)
    assert "lift uses the toy+base pairing" in text
    assert "positive:" in text
    assert text.count("\nscene 7: label") == 1
    assert images(nb) == 2
