"""The `relaff` command line as a user meets it: one-line user errors, tracebacks for bugs,
quiet imports, --set on every command, output paths checked before any work."""
import os
import subprocess
import sys

import pytest

from relaff_jax import cli
from relaff_jax.errors import UserError

COMMANDS = ("objects", "scenes", "generate", "info", "features", "show", "export", "experiment", "report",
            "reproduce")


def relaff(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "relaff_jax.cli", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_every_command_is_registered_and_every_stage_command_takes_set():
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(COMMANDS) <= set(sub.choices)
    for name in ("scenes", "generate", "features", "experiment", "report", "reproduce"):
        opts = {o for a in sub.choices[name]._actions for o in a.option_strings}
        assert "--set" in opts, name


def test_user_error_is_one_line_and_a_bug_keeps_its_traceback(monkeypatch, capsys):
    def user_mistake(args):
        raise UserError("the folder is a file")

    def bug(args):
        raise ValueError("an internal invariant broke")

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    objects = parser._subparsers._group_actions[0].choices["objects"]
    objects.set_defaults(func=user_mistake)
    assert cli.main(["objects"]) == 2
    err = capsys.readouterr().err
    assert err == "relaff objects: error: the folder is a file\n"
    objects.set_defaults(func=bug)
    with pytest.raises(ValueError, match="internal invariant"):  # not swallowed into a one-liner
        cli.main(["objects"])


def test_quiet_import_and_no_backend_change():
    code = ("import matplotlib; b = matplotlib.get_backend(); import relaff_jax, relaff_jax.report, "
            "relaff_jax.perception; from mujoco import mjx; assert matplotlib.get_backend() == b, "
            "(b, matplotlib.get_backend()); print('ok')")
    env = dict(os.environ, MPLBACKEND="svg")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout == "ok\n"
    assert "Failed to import" not in r.stderr + r.stdout


def test_objects_output_is_clean():
    r = relaff("objects", "--json")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(("[", "{"))
    assert r.stderr == ""


@pytest.mark.parametrize("argv", [
    ["experiment", "--data", "{d}", "--out", "{file}/results"],
    ["reproduce", "--preset", "tiny", "--out", "{file}"],
    ["reproduce", "--preset", "tiny", "--out", "{file}/run"],
    ["generate", "take", "--samples", "4", "--out", "{file}"],
    ["export", "{d}", "--format", "parquet", "--out", "{file}/x.parquet"],
])
def test_bad_output_paths_fail_at_once_with_one_line(tmp_path, argv):
    f = tmp_path / "a_file"
    f.write_text("not a folder")
    argv = [a.format(file=f, d=tmp_path) for a in argv]
    r = relaff(*argv)
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"relaff {argv[0]}: error:"), r.stderr


def test_unknown_set_key_lists_valid_keys(tmp_path):
    r = relaff("reproduce", "--preset", "tiny", "--out", str(tmp_path / "r"), "--set", "perception.voxel.sise=0.02")
    assert r.returncode == 2
    assert "unknown config key 'perception.voxel.sise'" in r.stderr
    assert "'size'" in r.stderr
    assert not (tmp_path / "r").exists()
