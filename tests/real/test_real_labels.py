"""Relation labels of real pairs: the labels file (round trip, every validation error), the
geometric rule on hand-worked synthetic pairs, and the CLI on the test scenes."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from relaff_jax.errors import UserError
from relaff_jax.real import labels as lab
from relaff_jax.config.real import RuleConfig
from relaff_jax.real.propose import overlap_fraction, propose_scene

from helpers import OSD

SHA = "ab" * 32


def box(lo, hi, n=600, seed=0):
    """Points (n, 3) filling the surface-ish volume of an axis-aligned box (table frame)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, size=(n, 3))


# ---- the labels file ---------------------------------------------------------------------

def test_round_trip(tmp_path):
    rows = [lab.Label("s1.pcd", 2, 3, "beside", SHA), lab.Label("s1.pcd", 4, 2, "on_top", SHA),
            lab.Label("s2.pcd", 3, 5, "on_top", "cd" * 32)]
    path = lab.write_labels(tmp_path / "l.csv", rows)
    assert path.read_text().splitlines()[0] == "scene,object_a,object_b,relation,sha256"
    assert lab.read_labels(path) == rows
    assert lab.relation_counts(rows) == {"beside": 1, "on_top": 2}


@pytest.mark.parametrize("text, message", [
    ("", "empty labels file"),
    ("scene,a,b,relation,sha256\n", "header is"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,2,3,inside," + SHA, "relation 'inside'"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,2,x,beside," + SHA, "object_b 'x'"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,1,3,beside," + SHA, "object_a 1 is not an object id"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,3,3,beside," + SHA, "both 3"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,2,3,beside,xyz", "not 64 hex digits"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,2,3,beside", "4 columns"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,2,3,beside," + SHA + "\ns.pcd,3,2,on_top," + SHA,
     "labelled twice"),
    ("scene,object_a,object_b,relation,sha256\ns.pcd,2,3,beside," + SHA + "\ns.pcd,2,4,beside," + "cd" * 32,
     "two different sha256"),
])
def test_format_errors(tmp_path, text, message):
    path = tmp_path / "l.csv"
    path.write_text(text)
    with pytest.raises(UserError, match=message):
        lab.read_labels(path)


def test_validate_errors(tmp_path):
    scene = tmp_path / "a.pcd"
    scene.write_bytes(b"scene bytes")
    good = lab.file_sha256(scene)
    ids = lambda p: [2, 3]
    ok = [lab.Label("a.pcd", 2, 3, "beside", good)]
    assert lab.validate(ok, tmp_path, ids) == ok
    with pytest.raises(UserError, match="unknown scene 'b.pcd'"):
        lab.validate([lab.Label("b.pcd", 2, 3, "beside", good)], tmp_path, ids)
    with pytest.raises(UserError, match="no object id 4"):
        lab.validate([lab.Label("a.pcd", 2, 4, "beside", good)], tmp_path, ids)
    with pytest.raises(UserError, match="checksum mismatch for a.pcd"):
        lab.validate([lab.Label("a.pcd", 2, 3, "beside", SHA)], tmp_path, ids)
    with pytest.raises(UserError, match="does not exist"):
        lab.read_labels(tmp_path / "missing.csv")


def test_shipped_labels_parse():
    from importlib.resources import files

    path = Path(str(files("relaff_jax.assets").joinpath("osd_learn_relations.csv")))
    rows = lab.read_labels(path)
    counts = lab.relation_counts(rows)
    assert counts["beside"] > 0
    assert counts["on_top"] > 0
    assert all(r.scene.startswith("learn") for r in rows)


# ---- the rule on hand-worked pairs ---------------------------------------------------------

def test_rule_on_top_upper_first():
    lower = box([0.0, 0.0, 0.0], [0.2, 0.2, 0.10])
    upper = box([0.05, 0.05, 0.10], [0.15, 0.15, 0.16], seed=1)
    (p,) = propose_scene({2: upper, 3: lower})
    assert (p.object_a, p.object_b, p.relation) == (2, 3, "on_top")
    (p,) = propose_scene({2: lower, 3: upper})  # ids the other way: still upper first
    assert (p.object_a, p.object_b, p.relation) == (3, 2, "on_top")


def test_rule_beside_and_hidden_bottom():
    a = box([0.0, 0.0, 0.0], [0.1, 0.1, 0.1])
    b = box([0.3, 0.0, 0.0], [0.4, 0.1, 0.2], seed=1)
    assert propose_scene({2: a, 3: b})[0].relation == "beside"
    # b's lower half hidden behind a: its visible bottom is high, but nothing is under it
    hidden = box([0.3, 0.0, 0.12], [0.4, 0.1, 0.2], seed=2)
    assert propose_scene({2: a, 3: hidden})[0].relation == "beside"


def test_rule_two_on_a_third_and_stack():
    base = box([0.0, 0.0, 0.0], [0.4, 0.2, 0.05])
    left = box([0.02, 0.02, 0.05], [0.15, 0.18, 0.12], seed=1)
    right = box([0.25, 0.02, 0.05], [0.38, 0.18, 0.10], seed=2)
    rel = {(p.object_a, p.object_b): p.relation for p in propose_scene({2: base, 3: left, 4: right})}
    assert rel == {(3, 2): "on_top", (4, 2): "on_top", (3, 4): "none"}
    top = box([0.05, 0.05, 0.12], [0.12, 0.15, 0.2], seed=3)  # on left, which is on base
    rel = {(p.object_a, p.object_b): p.relation for p in propose_scene({2: base, 3: left, 5: top})}
    assert rel == {(3, 2): "on_top", (2, 5): "none", (5, 3): "on_top"}


def test_rule_gap_and_no_overlap_are_not_on_top():
    lower = box([0.0, 0.0, 0.0], [0.2, 0.2, 0.10])
    floating = box([0.05, 0.05, 0.20], [0.15, 0.15, 0.26], seed=1)  # 10 cm above: no contact
    assert propose_scene({2: floating, 3: lower}, RuleConfig())[0].relation == "beside"
    assert overlap_fraction(box([0.5, 0.5, 0.1], [0.6, 0.6, 0.2]), lower, 0.01) == 0.0
    with pytest.raises(UserError, match="at least two objects"):
        propose_scene({2: lower})
    with pytest.raises(UserError, match="object 3 needs"):
        propose_scene({2: lower, 3: np.zeros((2, 3))})


# ---- on the real test scenes ---------------------------------------------------------------

@pytest.mark.slow
def test_cli_propose_check(tmp_path, capsys):
    from relaff_jax.cli import main

    scenes = tmp_path / "scenes"
    scenes.mkdir()
    for name in ("learn0.pcd", "learn17.pcd"):
        shutil.copy(OSD / name, scenes / name)
    out = tmp_path / "labels.csv"
    assert main(["real", "propose", str(scenes), "--out", str(out), "--pictures", str(tmp_path / "pics")]) == 0
    rows = lab.read_labels(out)
    assert {(r.scene, r.relation) for r in rows} == {("learn0.pcd", "beside"), ("learn17.pcd", "on_top")}
    assert len(list((tmp_path / "pics").glob("*.png"))) == 2
    assert main(["real", "check", str(scenes), "--labels", str(out)]) == 0
    assert "1 beside, 1 on_top" in capsys.readouterr().out
    corr = tmp_path / "corrections.csv"
    corr.write_text("scene,object_a,object_b,relation\nlearn0.pcd,3,2,none\n")  # ids either way round
    assert main(["real", "propose", str(scenes), "--out", str(out), "--corrections", str(corr)]) == 0
    assert [(r.scene, r.relation) for r in lab.read_labels(out)] == [("learn17.pcd", "on_top")]
    corr.write_text("scene,object_a,object_b,relation\nlearn0.pcd,2,4,beside\n")
    assert main(["real", "propose", str(scenes), "--out", str(out), "--corrections", str(corr)]) == 2
    assert "learn0.pcd has no object id 4" in capsys.readouterr().err  # checked before any proposal
    lab.write_labels(out, rows)
    (scenes / "learn0.pcd").write_bytes((scenes / "learn0.pcd").read_bytes() + b"\n")
    assert main(["real", "check", str(scenes), "--labels", str(out)]) == 2
    assert "checksum mismatch for learn0.pcd" in capsys.readouterr().err


def test_real_help_lists_subcommands(capsys):
    from relaff_jax.cli import main

    with pytest.raises(SystemExit):
        main(["real", "--help"])
    text = capsys.readouterr().out
    for cmd in ("segment", "show", "propose", "check", "study"):
        assert cmd in text
