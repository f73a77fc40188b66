"""Every key of the tree fed NaN, +-inf, -1, 1e20, 10**20, [], "foo" (as its type allows) through
the CLI's own checks (``precheck`` + ``resolve`` + ``check_tree``, as ``cli.options.config``
runs them): each is a ``UserError`` naming the key, or listed in ``VALID`` with a reason."""
from __future__ import annotations

import subprocess
import sys

import pytest

import relaff_jax.config as C
from relaff_jax.errors import UserError

NAN, INF = float("nan"), float("inf")

# (key, probe) -> why the value is genuinely valid
VALID = {
    ("action.arm.contact_face_cos", -1): "a cosine: -1 is in [-1, 1] (any contact normal counts)",
    ("action.phys.arm_max_geom_pairs", -1): "-1 is MJX's 'all pairs' (documented on the key)",
    ("experiment.state.extra", ()): "the default: no derived columns",
    ("action.scene.objects", ()): "the default: every object (the built-ins and the library file's)",
    ("experiment.learner", "foo"): "an import path: resolved and fitted once by learn.checks.check_config "
                                   "before the experiment reads any data (needs scikit-learn, not loaded here)",
}


def cli_check(overrides):
    C.precheck(overrides)
    return C.check_tree(C.resolve(None, overrides))


def _default(key):
    v = C.RunConfig()
    for k in key.split("."):
        v = getattr(v, k)
    return v


def _probes(v):
    if isinstance(v, bool):
        return [NAN, -1, "foo", ()]
    if isinstance(v, int):
        return [NAN, INF, -INF, -1, 1e20, 10**20, "foo", ()]
    if isinstance(v, float) or v is None:
        return [NAN, INF, -INF, -1, 1e20, "foo", ()]
    if isinstance(v, str):
        return ["foo", (), NAN]
    if isinstance(v, tuple):
        return [(), ("x",), (NAN,), (INF,), "foo", NAN, (-1,), (1e20,), ((),)]
    if isinstance(v, dict):
        return ["foo", (), NAN]
    raise TypeError(f"no probes for {v!r}")


CASES = [(k, p) for k in C.keys() for p in _probes(_default(k))]


def test_walk_covers_every_key():
    assert len(C.keys()) > 150 and len({k for k, _ in CASES}) == len(C.keys())


@pytest.mark.parametrize("key,probe", CASES, ids=[f"{k}={p!r}" for k, p in CASES])
def test_every_key_refuses_bad_values(key, probe):
    if (key, probe) in VALID:
        cli_check({key: probe})  # genuinely valid: accepted
        return
    with pytest.raises(UserError) as e:
        cli_check({key: probe})
    msg = str(e.value)
    assert f"'{key}'" in msg and "\n" not in msg, msg


@pytest.mark.parametrize("key,value,words", [
    ("perception.camera.position", (), "a list of 3 values"),
    ("experiment.bf_sizes", (), "a list of 2 values"),
    ("experiment.sizes", ("x",), "strictly increasing"),
    ("experiment.forest.engine", "foo", "one of fast, sklearn, compiled"),  # real.experiment's engine
    ("real.experiment.n_boot", 0, "an integer in [10, 10000000]"),
    ("real.sim.noise", "foo", "one of robwork"),
    ("perception.voxel.size", NAN, "a finite number in (0.0, 1.0]"),
    ("perception.camera.width", 10**20, "an integer in [1, 8192]"),
])
def test_named_cases_are_one_line(key, value, words):
    with pytest.raises(C.ConfigError, match=r"config key '%s' must be " % key.replace(".", r"\.")) as e:
        cli_check({key: value})
    assert words in str(e.value)


def test_presets_pass_and_defaults_are_unchanged():
    for name in C.PRESETS:
        C.check_tree(C.preset(name))
    d = C.to_dict(C.RunConfig())
    assert d["perception"]["voxel"] == {"size": 0.0125, "max_object_pixels": 32768, "max_voxels": 4096}
    assert d["experiment"]["forest"]["base_trees"] == 95 and d["dataset"]["n_samples"] == 10_000


@pytest.mark.parametrize("argv", [
    ["features", "DS", "--set", "perception.voxel.size=NaN"],
    ["real", "propose", "SCENES", "--out", "OUT", "--set", "real.rule.contact_tol=NaN"],
    ["generate", "lift", "--samples", "8", "--out", "OUT", "--set", "perception.camera.width=1e20"],
])
def test_cli_refuses_nan_in_one_line(argv, tmp_path):
    argv = [str(tmp_path / a) if a in ("DS", "SCENES", "OUT") else a for a in argv]
    code = ("import sys\nfrom relaff_jax.cli import main\nrc = main(sys.argv[1:])\n"
            "heavy = [m for m in ('jax', 'mujoco', 'sklearn') if m in sys.modules]\n"
            "sys.exit(rc if not heavy else f'imported {heavy}')\n")
    r = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    key = argv[argv.index("--set") + 1].split("=")[0]
    assert len(lines) == 1 and lines[0].startswith(f"relaff {argv[0]}") and f"config key '{key}'" in lines[0], lines


@pytest.mark.parametrize("argv", [
    ["generate", "lift", "--samples", "8", "--out", "OUT", "--seed", "3", "--set", "seed=4"],
    ["features", "OUT", "--seed", "3", "--set", "seed=4"],
    ["reproduce", "--preset", "tiny", "--out", "OUT", "--seed", "3", "--set", "seed=4"],
])
def test_seed_flag_is_the_tree_key(argv, tmp_path, capsys):
    from relaff_jax import cli

    argv = [str(tmp_path / a) if a == "OUT" else a for a in argv]
    if argv[0] == "features":
        (tmp_path / "OUT").mkdir()
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("--seed 3 and --set seed=4 disagree; give one of them") and "\n" not in err, err
    assert C.resolve(None, {"seed": 4}).seed == 4 and C.RunConfig().seed == 0
