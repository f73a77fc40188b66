"""The table of damaged and foreign inputs, through the real CLI (``cli.main``):
each case exits 2 with one line ``relaff CMD: error: ...`` naming what is wrong, prints no
traceback, and writes nothing into its output folder before refusing.

Inputs are tiny and made here (a synthetic experiment folder, report JSON files, a dataset
sidecar, labels files beside a copy of a shipped scene); no case simulates or fits."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from relaff_jax import cli

from helpers import OSD



def no_work(*args, **kwargs):
    raise AssertionError("the work started before the inputs were checked")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    from relaff_jax.config.experiment import ExperimentConfig
    from relaff_jax.learn.synthetic_results import write_synthetic_results

    cfg = ExperimentConfig(sizes=(2, 4, 10), reps_pca=2, reps_rhf=2, test_size=24, ci_resamples=10)
    return write_synthetic_results(tmp_path_factory.mktemp("syn") / "results", cfg, seed=1)


def _report(root: Path, name: str, **override) -> Path:
    """A report folder with the three JSON files ``relaff compare`` reads (minimal content);
    ``override``: file stem -> text to write instead."""
    d = root / name
    d.mkdir()
    files = {"reach": json.dumps({"datasets": {}, "spaces": {"pca": {"sizes": [2, 10]}}}),
             "findings": json.dumps({"findings": []}), "summary": json.dumps({})}
    for stem, text in {**files, **override}.items():
        (d / f"{stem}.json").write_text(text)
    return d


def _sidecar(root: Path, name: str, **fields) -> Path:
    from relaff_jax.data.layout import FORMAT, FORMAT_VERSION, SIDECAR

    d = root / name
    d.mkdir()
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "action": "lift", "n_samples": 4, "seed": 0,
            "batch": 8, "status": "complete", "counts": {"chunks": 1, "rollouts": 8, "positives": 2}, **fields}
    (d / SIDECAR).write_text(json.dumps(meta))
    (d / "chunks").mkdir()  # the sidecar records a chunk the folder does not hold: truncated
    return d


def _scenes(root: Path) -> Path:
    d = root / "scenes"
    d.mkdir()
    shutil.copy(OSD / "learn0.pcd", d / "learn0.pcd")
    return d


def _labels(root: Path, body: bytes, name: str = "labels.csv") -> Path:
    p = root / name
    p.write_bytes(body)
    return p


SHA = "0" * 64


def case_long_out(t, results):
    return ["experiment", "--synthetic", "10", "--out", str(t / "out" / ("a" * 300) / "x")], "255"


def case_info_wrong_types(t, results):
    return ["info", str(_sidecar(t, "ds", counts="x", n_samples="four"))], "should be"


def case_report_foreign_meta(t, results):
    r = t / "res"
    shutil.copytree(results, r)
    (r / "experiment.json").write_text(json.dumps({"hello": 1}))
    return ["report", str(r), "--out", str(t / "out")], "not an experiment record"


def case_report_corrupt_meta(t, results):
    r = t / "res"
    shutil.copytree(results, r)
    (r / "experiment.json").write_text('{"actions": [')
    return ["report", str(r), "--out", str(t / "out")], "corrupt JSON"


def case_report_truncated_npz(t, results):
    r = t / "res"
    shutil.copytree(results, r)
    p = r / "pca" / "results.npz"
    p.write_bytes(p.read_bytes()[:500])
    return ["report", str(r), "--out", str(t / "out")], "results.npz: truncated"


def case_compare_corrupt_findings(t, results):
    b = _report(t, "b", findings='{"findings": [')
    return ["compare", f"a={_report(t, 'a')}", f"b={b}",
            "--out", str(t / "out" / "c.md")], "findings.json: corrupt JSON"


def case_compare_corrupt_summary(t, results):
    return ["compare", f"a={_report(t, 'a')}", f"b={_report(t, 'b', summary='[1,2')}",
            "--out", str(t / "out" / "c.md")], "summary.json: corrupt JSON"


def case_compare_foreign_reach(t, results):
    return ["compare", f"a={_report(t, 'a')}", f"b={_report(t, 'b', reach='[]')}",
            "--out", str(t / "out" / "c.md")], "not a relaff report file"


def case_experiment_negative_synthetic(t, results):
    return ["experiment", "--synthetic", "-5", "--out", str(t / "out")], "--synthetic"


def case_experiment_too_few_synthetic_samples(t, results):
    return ["experiment", "--synthetic", "5", "--out", str(t / "out")], "5 samples, but the protocol needs"


def case_real_check_latin1(t, results):
    lab = _labels(t, b"scene,object_a,object_b,relation,sha256\nlearn0\xe9.pcd,2,3,beside," + SHA.encode() + b"\n")
    return ["real", "check", str(_scenes(t)), "--labels", str(lab)], "not UTF-8"


def case_real_study_negative_seed(t, results):
    lab = _labels(t, f"scene,object_a,object_b,relation,sha256\nlearn0.pcd,2,3,beside,{SHA}\n".encode())
    return ["real", "study", str(_scenes(t)), "--labels", str(lab), "--seed", "-1", "--out", str(t / "out")], "--seed"


def case_real_check_scene_outside(t, results):
    lab = _labels(t, f"scene,object_a,object_b,relation,sha256\n../../etc/passwd,2,3,beside,{SHA}\n".encode())
    return ["real", "check", str(_scenes(t)), "--labels", str(lab)], "not a file name in the scenes folder"


def case_real_check_absolute_scene(t, results):
    lab = _labels(t, f"scene,object_a,object_b,relation,sha256\n/etc/passwd,2,3,beside,{SHA}\n".encode())
    return ["real", "check", str(_scenes(t)), "--labels", str(lab)], "no folders"


def case_real_check_no_sha_column(t, results):
    lab = _labels(t, b"scene,object_a,object_b,relation\nlearn0.pcd,2,3,beside\n")
    return ["real", "check", str(_scenes(t)), "--labels", str(lab)], "--write-checksums"


def case_compare_negative_size(t, results):
    return ["compare", f"a={_report(t, 'a')}", f"b={_report(t, 'b')}", "--size", "-3",
            "--out", str(t / "out" / "c.md")], "--size"


def case_compare_size_not_run(t, results):
    return ["compare", f"a={_report(t, 'a')}", f"b={_report(t, 'b')}", "--size", "7",
            "--out", str(t / "out" / "c.md")], "not a training size"


def case_compare_same_folder_twice(t, results):
    a = _report(t, "a")
    return ["compare", f"a={a}", f"b={a}/", "--out", str(t / "out" / "c.md")], "same folder"


def case_report_data_unknown_action(t, results):
    return ["report", str(results), "--out", str(t / "out"), "--data", str(_sidecar(t, "ds", action="fly"))], "'fly'"


def case_report_data_truncated(t, results):
    return ["report", str(results), "--out", str(t / "out"), "--data", str(_sidecar(t, "ds"))], "truncated"


def case_generate_foreign_out(t, results):
    out = t / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    return ["generate", "lift", "--samples", "4", "--out", str(out)], "not a relaff dataset"


def case_generate_negative_seed(t, results):
    return ["generate", "lift", "--samples", "4", "--seed", "-1", "--out", str(t / "out")], "--seed"


def case_reproduce_force_report_symlink(t, results):
    out, elsewhere = t / "out", t / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / "report").symlink_to(elsewhere)
    return ["reproduce", "--preset", "tiny", "--out", str(out), "--force", "report"], "symbolic link"


def case_reproduce_redo_dataset_symlink(t, results):
    out, elsewhere = t / "out", t / "elsewhere"
    (out / "data").mkdir(parents=True)
    elsewhere.mkdir()
    (out / "data" / "lift").symlink_to(elsewhere)
    return ["reproduce", "--preset", "tiny", "--out", str(out), "--redo-dataset", "lift"], "symbolic link"


def case_propose_bad_corrections(t, results):
    corr = _labels(t, b"scene,object_a,object_b,relation\nlearn0.pcd,2,3,stacked\n", "corr.csv")
    return ["real", "propose", str(_scenes(t)), "--out", str(t / "out" / "labels.csv"),
            "--corrections", str(corr)], "relation 'stacked'"


CASES = {k[5:]: v for k, v in dict(globals()).items() if k.startswith("case_")}


def _snapshot(out: Path) -> set:
    return {p.relative_to(out) for p in out.rglob("*")} if out.is_dir() else set()


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input_is_one_line_before_any_work(name, tmp_path, results, capsys, monkeypatch):
    import relaff_jax.real.stages
    import relaff_jax.stages.generate

    monkeypatch.setattr(relaff_jax.real.stages, "propose_folder", no_work)  # where real propose calls it
    monkeypatch.setattr(relaff_jax.stages.generate, "generate_one", no_work)
    argv, expect = CASES[name](tmp_path, results)
    out = tmp_path / "out"
    before = _snapshot(out)
    code = cli.main(argv)
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if x.strip()]
    command = " ".join(argv[:2]) if argv[0] == "real" else argv[0]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith(f"relaff {command}: error: "), err
    assert "Traceback" not in err and expect in lines[0], err
    if name != "reproduce_force_report_symlink" and name != "reproduce_redo_dataset_symlink":
        assert _snapshot(out) == before, f"{name} wrote into its output folder before refusing"


def test_a_bom_labels_file_is_read(tmp_path):
    from relaff_jax.real import labels as lab

    rows = lab.parse_labels(f"\ufeffscene,object_a,object_b,relation,sha256\nlearn0.pcd,2,3,beside,{SHA}\n", "x")
    assert rows == [lab.Label("learn0.pcd", 2, 3, "beside", SHA)]
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbfscene,object_a,object_b,relation,sha256\nlearn0.pcd,2,3,beside," + SHA.encode() + b"\n")
    assert lab.read_labels(p) == rows


def test_write_checksums_adds_the_sha256_column(tmp_path, capsys):
    from relaff_jax.real import labels as lab

    scenes = _scenes(tmp_path)
    p = _labels(tmp_path, b"scene,object_a,object_b,relation\nlearn0.pcd,2,3,beside\n")
    assert cli.main(["real", "check", str(scenes), "--labels", str(p), "--write-checksums"]) == 0
    rows = lab.read_labels(p)
    assert [r.sha256 for r in rows] == [lab.file_sha256(scenes / "learn0.pcd")]
    assert "valid" in capsys.readouterr().out


def test_the_lock_never_follows_a_symlink(tmp_path):
    from relaff_jax.errors import UserError
    from relaff_jax.io import folder_lock

    target = tmp_path / "victim"
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / ".relaff.lock").symlink_to(target)  # dangling: the lock would create it
    with pytest.raises(UserError, match="symbolic link"):
        with folder_lock(tmp_path / "d", "busy"):
            pass
    assert not target.exists()


def test_remove_tree_refuses_a_link_and_keeps_its_target(tmp_path):
    from relaff_jax.errors import UserError
    from relaff_jax.io import remove_tree

    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "keep").write_text("x")
    (tmp_path / "link").symlink_to(tmp_path / "t")
    with pytest.raises(UserError, match="symbolic link"):
        remove_tree(tmp_path / "link")
    assert (tmp_path / "t" / "keep").exists()


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("relaff ")


def _pcd(tmp_path, name, data: bytes, points: int) -> Path:
    head = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
            f"WIDTH {points}\nHEIGHT 1\nPOINTS {points}\n")
    p = tmp_path / name
    p.write_bytes(head.encode() + data)
    return p


@pytest.mark.parametrize("kind, points, expect", [
    ("ascii_more_values", 2, "does not match the data"),
    ("binary_trailing", 2, "does not match the data"),
    ("ascii_inf", 3, "infinite"),
])
def test_pcd_damage_is_named(tmp_path, kind, points, expect):
    from relaff_jax.errors import UserError
    from relaff_jax.real.pcd import read_pcd

    xyz = np.arange(9, dtype="<f4").reshape(3, 3)
    if kind == "ascii_more_values":
        data = b"DATA ascii\n" + b"\n".join(b" ".join(b"%g" % v for v in r) for r in xyz) + b"\n"
    elif kind == "binary_trailing":
        data = b"DATA binary\n" + xyz.tobytes()
    else:
        data = b"DATA ascii\n0 0 0\n1 inf 1\n2 2 2\n"
    with pytest.raises(UserError, match=expect):
        read_pcd(_pcd(tmp_path, "c.pcd", data, points))


def test_pcd_zero_padding_after_the_data_is_accepted(tmp_path):
    from relaff_jax.real.pcd import read_pcd

    xyz = np.arange(9, dtype="<f4").reshape(3, 3)
    c = read_pcd(_pcd(tmp_path, "c.pcd", b"DATA binary\n" + xyz.tobytes() + b"\0" * 64, 3))
    np.testing.assert_array_equal(c.xyz, xyz)


def test_a_scene_without_objects_is_refused_not_nan(tmp_path, capsys):
    from relaff_jax.real.cloud import make_cloud
    from relaff_jax.real.pcd import write_pcd

    h, w = 24, 32
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    xyz = np.stack([(u - w / 2) * 0.01, (v - h / 2) * 0.01, np.full((h, w), 1.0, np.float32)], -1)
    (tmp_path / "s").mkdir()
    write_pcd(tmp_path / "s" / "plane.pcd", make_cloud(xyz, label=np.full((h, w), 10, np.uint32)))
    assert cli.main(["real", "segment", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert "holds no object" in err and "Traceback" not in err


def test_a_full_disk_is_one_line_naming_the_folder(tmp_path, capsys, monkeypatch):
    """ENOSPC in an atomic write: one line naming the folder and the size of the write; the
    old file is untouched and no temporary file is left."""
    import errno

    from relaff_jax import io as rio

    target = tmp_path / "out" / "f.json"
    rio.atomic_write_json(target, {"old": 1})
    real_fsync = os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    from relaff_jax.errors import DiskFullError

    with pytest.raises(DiskFullError, match=f"no space left in {tmp_path / 'out'}.*needed"):
        rio.atomic_write_json(target, {"new": 2})
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert json.loads(target.read_text()) == {"old": 1}
    assert [p.name for p in target.parent.iterdir()] == ["f.json"]


def test_a_full_disk_anywhere_is_one_line_from_the_cli(tmp_path, capsys, monkeypatch):
    import errno

    import relaff_jax.cli.data as cd

    def full(args):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "x" / "y.npz"))

    monkeypatch.setattr(cd, "_cmd_info", full)
    assert cli.main(["info", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"no space left in {tmp_path / 'x'}" in err[0]


def test_the_dataset_writer_lock_never_follows_a_symlink(tmp_path):
    from relaff_jax.data import DatasetError
    from relaff_jax.data.layout import LOCK
    from relaff_jax.data.store import writer_lock

    target = tmp_path / "victim"
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / LOCK).symlink_to(target)
    with pytest.raises(DatasetError, match="symbolic link"):
        with writer_lock(tmp_path / "d"):
            pass
    assert not target.exists()


def test_damaged_cloud_files_are_user_errors_never_tracebacks(tmp_path):
    """Truncations, byte flips, inserted bytes, deleted and replaced header tokens of a small
    cloud in every format: each read either succeeds or is a ``UserError``."""
    import re
    import warnings

    from relaff_jax.errors import UserError
    from relaff_jax.real.cloud import make_cloud
    from relaff_jax.real.pcd import write_pcd
    from relaff_jax.real.ply import write_ply
    from relaff_jax.real.readers import read_cloud, write_npz

    rng = np.random.default_rng(2)
    c = make_cloud(rng.normal(size=(6, 8, 3)).astype(np.float32), rgb=rng.integers(0, 255, (6, 8, 3)).astype(np.uint8),
                   label=rng.integers(0, 50, (6, 8)).astype(np.uint32))
    files = []
    for mode in ("ascii", "binary", "binary_compressed"):
        write_pcd(tmp_path / f"{mode}.pcd", c, mode)
        files.append(tmp_path / f"{mode}.pcd")
    write_ply(tmp_path / "c.ply", c)
    write_npz(tmp_path / "c.npz", c)
    files += [tmp_path / "c.ply", tmp_path / "c.npz"]
    for f in files:
        raw = f.read_bytes()
        head = max(raw.find(b"DATA") if f.suffix == ".pcd" else raw.find(b"end_header"), 1)
        for _ in range(150):
            b, k = bytearray(raw), rng.integers(0, 5)
            if k == 0:
                b = b[:rng.integers(0, len(b))]
            elif k == 1:
                for _ in range(rng.integers(1, 4)):
                    b[rng.integers(0, head + 20)] = rng.integers(0, 256)
            elif k == 2:
                i = rng.integers(0, len(b))
                b = b[:i] + bytes(rng.integers(0, 256, rng.integers(1, 20)).astype(np.uint8)) + b[i:]
            else:
                toks = list(re.finditer(rb"\S+" if k == 3 else rb"\d+", bytes(b[:head])))
                if not toks:  # .npz: no text header
                    continue
                m = toks[rng.integers(0, len(toks))]
                b = b[:m.start()] + (b"" if k == 3 else str(rng.choice([0, 1, -1, 7, 10**12])).encode()) + b[m.end():]
            q = tmp_path / f"damaged{f.suffix}"
            q.write_bytes(bytes(b))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    read_cloud(q)
                except UserError:
                    pass


def test_a_full_disk_under_orbax_is_one_line_and_leaves_no_chunk(tmp_path, monkeypatch):
    """tensorstore reports ENOSPC as a ValueError ("RESOURCE_EXHAUSTED ... [os_error_code='28']"):
    a chunk write that meets it is a ``DiskFullError`` naming the chunks folder, and no
    temporary chunk folder is left."""
    from relaff_jax.data import store
    from relaff_jax.errors import DiskFullError

    class Full:
        def save(self, *a, **k):
            raise ValueError("RESOURCE_EXHAUSTED: Error writing local file \"/x/manifest.ocdbt\": "
                             "No space left on device [os_error_code='28']")

    monkeypatch.setattr(store, "_checkpointer", lambda: Full())
    (tmp_path / "chunks").mkdir()
    with pytest.raises(DiskFullError, match=f"no space left in {tmp_path / 'chunks'}"):
        store.write_chunk(tmp_path / "chunks" / "chunk_000000", {"label": np.zeros(8, bool)}, {})
    assert list((tmp_path / "chunks").iterdir()) == []
