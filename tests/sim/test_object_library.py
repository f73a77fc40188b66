"""Object library files (sim/object_library.py): the built-ins round-trip through the file
format, every refusal is one line naming the object and field, the resolved objects are
recorded in a dataset with a sha256 and a resume with other objects is refused, and a scene
with a user object is sampled and settled (docs/objects.md)."""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

import relaff_jax  # noqa: F401 (XLA flags before JAX)
from relaff_jax import cli
from relaff_jax import data as ds
from relaff_jax.errors import UserError
from relaff_jax.sim import object_library as ol
from relaff_jax.sim import objects as lib
from relaff_jax.config.action import ActionConfig, SceneConfig
from relaff_jax.config.dataset import DatasetConfig

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "my_objects.toml"


@pytest.fixture(autouse=True)
def builtins_after():
    """Every test leaves the built-ins active, whatever it activated."""
    yield
    lib.activate(lib.BUILTIN_SET)


def dish(**changes) -> dict:
    """The example file's dish as a table, with ``changes`` (None deletes a key)."""
    d = tomllib.loads(EXAMPLE.read_text())["object"][0]
    for k, v in changes.items():
        if v is None:
            d.pop(k)
        else:
            d[k] = v
    return d


def write(tmp_path: Path, objs: list, suffix: str = ".toml") -> Path:
    """A library file of the tables ``objs`` (TOML inline tables, or JSON)."""
    p = tmp_path / f"lib{suffix}"
    p.write_text(json.dumps({"object": objs}) if suffix == ".json" else _raw_toml(objs))
    return p


def _raw_toml(objs) -> str:  # tables the parser refuses, written as JSON-like TOML inline values
    out = []
    for o in objs:
        out.append("[[object]]")
        for k, v in o.items():
            out.append(f"{k} = {_val(v)}")
    return "\n".join(out) + "\n"


def _val(v) -> str:
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_val(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_val(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if v != v else ("inf" if v > 0 else "-inf")
    return repr(v)


def test_builtins_round_trip_through_toml_and_json(tmp_path):
    specs = tuple(lib.OBJECTS.values())
    for text in (ol.to_toml(specs), json.dumps({"object": [ol.spec_dict(s) for s in specs]})):
        doc = tomllib.loads(text) if text.startswith("[[") else json.loads(text)
        back = tuple(ol.parse_spec(d, "round trip") for d in doc["object"])
        assert back == specs  # every field, kind (derived) included, bit for bit
    # the file form's hash is the record's: one spec changed changes it
    assert ol.digest(specs) != ol.digest(specs[:-1])


def test_example_file_loads_and_merges():
    user = ol.load_library(EXAMPLE)
    assert [s.name for s in user] == ["dish"]
    d = user[0]
    assert d.kind == "container" and d.groups == ("base",) and d.inner == (0.102, 0.102, 0.05)
    objs = ol.select(user, ())
    assert [s.name for s in objs.specs] == list(lib.OBJECTS) + ["dish"]
    assert len(objs.pairs()) == 124 + 5  # one more base for each of the five toys
    narrow = ol.select(user, ("ball", "cup", "dish"))
    assert narrow.pairs() == (("ball", "cup", "toy+base"), ("ball", "dish", "toy+base"),
                              ("cup", "dish", "toy+base"))
    # the default scene settings select the built-ins, the very set every run used before
    assert ol.scene_objects(SceneConfig()) is lib.BUILTIN_SET


REFUSALS = [
    (dict(colour_x=[1, 0, 0]), r"object 'dish': unknown key 'colour_x'; valid keys"),
    (dict(groups=["bowl"]), r"object 'dish': groups: unknown group 'bowl'; valid groups: toy, base, obstacle, rake"),
    (dict(groups=["toy", "obstacle"]), r"object 'dish': groups .*a toy may only also be a base"),
    (dict(mass=0.0), r"object 'dish': mass must be a finite number > 0, got 0.0"),
    (dict(mass=float("nan")), r"object 'dish': mass must be a finite number > 0, got nan"),
    (dict(friction=-1.0), r"object 'dish': friction must be a finite number > 0"),
    (dict(mass=None), r"object 'dish': mass is missing"),
    (dict(colour=[0.9, 0.12, 0.1]), r"object 'dish': colour \[0.9, 0.12, 0.1\] is 0.020 from the colour of 'ball'"),
    (dict(colour=[1.2, 0.0, 0.0]), r"object 'dish': colour must be RGB in \[0, 1\]"),
    (dict(name="bowl"), r"object 'bowl': name clashes with a built-in object"),
    (dict(inner=[0.2, 0.1, 0.03]), r"object 'dish': inner \[0.2, 0.1, 0.03\]: the inner half-extents must be smaller"),
    (dict(sphere_radius=0.03), r"object 'dish': sphere_radius: only a toy can be a ball"),
]


@pytest.mark.parametrize("changes, match", REFUSALS)
def test_refusals_name_the_object_and_field(tmp_path, changes, match):
    p = write(tmp_path, [dish(**changes)])
    with pytest.raises(UserError, match=match) as e:
        ol.load_library(p)
    assert "\n" not in str(e.value) and str(e.value).startswith(f"object library {p}: ")


def test_part_and_size_refusals(tmp_path):
    parts = dish()["parts"]
    cases = [
        (dict(parts={**parts, "lid": parts["base"]}),
         r"parts.lid: not a slot of the template \(the other slot's boxes: base, wall_xp, wall_xn, wall_yp, wall_yn\)"),
        (dict(parts={**parts, "base": {"size": [0.22, float("inf"), 0.01]}}),
         r"parts.base.size\[1\] must be a finite number > 0, got inf"),
        (dict(parts={**parts, "base": {"size": [0.22, 0.22, -0.01]}}), r"parts.base.size\[2\] must be a finite number > 0"),
        (dict(parts={k: v for k, v in parts.items() if k != "base"}, inner=None), r"parts.base is missing"),
        (dict(parts={**parts, "base": {"size": [0.22, 0.22, 0.01], "centre": [0, 0, 0.005], "colour": 1}}),
         r"parts.base: unknown key 'colour'"),
    ]
    for changes, match in cases:
        with pytest.raises(UserError, match=match):
            ol.load_library(write(tmp_path, [dish(**changes)]))
    # a toy's only part is the toy slot's box
    toy = {"name": "cube2", "groups": ["toy"], "mass": 0.1, "friction": 0.9, "colour": [0.5, 0.5, 0.9],
           "parts": {"base": {"size": [0.05, 0.05, 0.05]}}}
    with pytest.raises(UserError, match=r"object 'cube2': parts.base: not a slot of the template \(the toy slot's box: box\)"):
        ol.load_library(write(tmp_path, [toy]))


def test_gripper_and_table_region_refusals(tmp_path):
    # a toy 40 cm across its narrower side: each finger opens at most 0.21 m to half of it + 2 cm
    toy = {"name": "crate", "groups": ["toy"], "mass": 0.5, "friction": 0.9, "colour": [0.5, 0.5, 0.9],
           "parts": {"box": {"size": [0.40, 0.50, 0.1]}}}
    with pytest.raises(UserError, match=r"object 'crate': a toy 40.0 cm across .* more than the gripper can hold"):
        ol.load_library(write(tmp_path, [toy]))
    toy["parts"]["box"]["size"] = [0.36, 0.50, 0.1]  # 0.18 + 0.02 <= 0.21: holdable
    assert ol.load_library(write(tmp_path, [toy]))[0].name == "crate"
    # a base wider than the half-annulus scenes sample (0.2 .. 1.8 m: 1.6 m for a footprint diameter)
    wide = dish(parts={"base": {"size": [1.2, 1.2, 0.02]}}, inner=None)
    with pytest.raises(UserError, match=r"object 'dish': footprint radius 0.849 m does not fit the table region"):
        ol.load_library(write(tmp_path, [wide]))
    with pytest.raises(UserError, match="does not fit"):  # the scene settings decide the region
        ol.load_library(write(tmp_path, [dish()]), SceneConfig(workspace_radius=0.4, min_radius=0.2))


def test_file_level_refusals(tmp_path):
    with pytest.raises(UserError, match=r"must be a .toml or .json file"):
        ol.load_library(tmp_path / "objs.yaml")
    with pytest.raises(UserError, match=r"cannot be read"):
        ol.load_library(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[[object]\nname=1")
    with pytest.raises(UserError, match=r"is not valid TOML"):
        ol.load_library(bad)
    bad.write_text('version = 2\n[[object]]\nname = "x"\n')
    with pytest.raises(UserError, match=r"unknown top-level key 'version'"):
        ol.load_library(bad)
    twice = write(tmp_path, [dish(), dish(colour=[0.3, 0.3, 0.1])], ".json")
    with pytest.raises(UserError, match=r"object 'dish': defined twice"):
        ol.load_library(twice)
    with pytest.raises(UserError, match=r"config key 'action.scene.objects': unknown object 'plate2'; valid objects: ball,"):
        ol.select((), ("ball", "plate2"))
    with pytest.raises(UserError, match=r"selects no toy"):
        ol.select((), ("plate", "bowl"))
    with pytest.raises(UserError, match=r"selects no object to pair with a toy"):
        ol.select((), ("ball", "block"))


def test_cli_lists_merged_set_and_refuses_in_one_line(tmp_path, capsys):
    assert cli.main(["objects", "--json", "--library", str(EXAMPLE)]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == list(lib.OBJECTS) + ["dish"]
    assert rows[-1] == {"name": "dish", "group": "base", "groups": ["base"], "kind": "container",
                        "colour": [0.05, 0.55, 0.3], "mass_kg": 0.3, "size_cm": [22.0, 22.0, 5.0], "container": True}
    bad = write(tmp_path, [dish(name="plate")])
    assert cli.main(["objects", "--library", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "name clashes with a built-in object" in err[0] and err[0].startswith("relaff objects: error:")


def test_config_tree_checks_the_library_before_any_work(tmp_path):
    from relaff_jax.config import check_tree, resolve

    bad = write(tmp_path, [dish(mass=-1.0)])
    with pytest.raises(UserError, match=r"object 'dish': mass must be a finite number > 0"):
        check_tree(resolve(None, {"action.scene.library": str(bad)}))
    tree = check_tree(resolve(None, {"action.scene.library": str(EXAMPLE),
                                     "action.scene.objects": ("ball", "toy_can", "dish")}))
    assert [s.name for s in lib.active().specs] == ["ball", "toy_can", "dish"]
    check_tree(resolve(None, {}))  # the defaults: the built-ins again
    assert lib.active() is lib.BUILTIN_SET
    with pytest.raises(UserError, match=r"'action.scene.objects' .*expects a list"):
        resolve(None, {"action.scene.objects": "ball"})
    with pytest.raises(UserError, match=r"'action.scene.objects' must be a list of values, distinct, each an object name"):
        resolve(None, {"action.scene.objects": (1, 2)})
    assert tree.action.scene.library == str(EXAMPLE)


def _synthetic(key, b):
    rng = np.random.default_rng(np.asarray(key).tolist())
    return {"label": rng.random(b) < 0.5, "relation": np.asarray(ds.RELATIONS)[rng.integers(0, 3, b)],
            "cog_distance": rng.uniform(0.05, 0.5, b).astype(np.float32),
            "toy": np.asarray(["ball"] * b), "other": np.asarray(["dish"] * b)}


def test_recorded_objects_and_resume_with_a_changed_file_refused(tmp_path):
    """The factory records the resolved specs and their sha256; a dataset resumed with the file
    changed is refused in one line; the record alone rebuilds the set (the file may be gone);
    an old sidecar (no record) reads as the built-ins."""
    from relaff_jax.io import read_json
    from relaff_jax.sim.templates import stored_config

    libfile = tmp_path / "mine.toml"
    libfile.write_text(EXAMPLE.read_text())
    cfg = ActionConfig(scene=SceneConfig(library=str(libfile), objects=("ball", "dish")))
    assert "library" not in stored_config(ActionConfig())["scene"]  # built-ins: recorded as before
    rec = ol.record(ol.use_scene(cfg.scene))
    assert rec["names"] == ["ball", "dish"] and [d["name"] for d in rec["specs"]] == ["dish"]
    config = {"action": "lift", "action_config": stored_config(cfg), "objects": rec}
    out = tmp_path / "ds"
    dcfg = DatasetConfig(max_rollouts=64, distance_bins=2, borrow_fraction=1.0, n_samples=4, rollout_batch=16)
    ds.generate_dataset(out, "lift", _synthetic, 0, config, progress=False, dataset_config=dcfg)
    meta = read_json(out / ds.SIDECAR)
    assert meta["config"]["objects"]["sha256"] == ol.digest(lib.active().specs) == rec["sha256"]

    libfile.write_text(EXAMPLE.read_text().replace("mass = 0.30", "mass = 0.35"))
    lib.activate(lib.BUILTIN_SET)
    rec2 = ol.record(ol.use_scene(cfg.scene))
    assert rec2["sha256"] != rec["sha256"]
    with pytest.raises(ds.DatasetMismatchError, match=r"was generated with objects [0-9a-f]{12} .*resuming would "
                                                       r"mix two object sets") as e:
        ds.generate_dataset(out, "lift", _synthetic, 0, {**config, "objects": rec2}, progress=False,
                            dataset_config=dcfg)
    assert "\n" not in str(e.value)
    with pytest.raises(ds.DatasetMismatchError, match=r"this run resolves to the 29 built-in objects"):
        ds.generate_dataset(out, "lift", _synthetic, 0, {k: v for k, v in config.items() if k != "objects"},
                            progress=False, dataset_config=dcfg)

    libfile.unlink()
    objs = ol.use_recorded(meta)  # the record, not the file
    assert [s.name for s in objs.specs] == ["ball", "dish"] and objs.get("dish").mass == 0.30
    assert ol.use_recorded({"config": {"action": "lift"}}) is lib.BUILTIN_SET


@pytest.mark.slow
def test_user_object_world_is_one_model_structure():
    """The built-ins plus the dish: the same mjx.Model tree, the same pair-batched fields (the
    dish is sizes, masses and colours in the template), one more axis entry per dish pair."""
    import jax

    from relaff_jax.sim import world as wd

    base = wd.build_world()
    lib.activate(ol.select(ol.load_library(EXAMPLE), ()))
    world = wd.build_world()
    assert world.n_pairs == base.n_pairs + 5
    idx = [world.pair_id(t, o) for t, o, _ in base.pairs]  # the dish's pairs sit among the toy+base ones
    assert [world.pairs[i] for i in idx] == list(base.pairs)
    assert world.batched_fields == base.batched_fields
    assert jax.tree_util.tree_structure(world.model) == jax.tree_util.tree_structure(base.model)
    lw, tdef = jax.tree_util.tree_flatten(world.model)
    lb, _ = jax.tree_util.tree_flatten(base.model)
    axes = tdef.flatten_up_to(world.model_axes)
    assert axes == tdef.flatten_up_to(base.model_axes)
    for x, y, a in zip(lw, lb, axes):  # the built-in pairs' values are the built-in world's, bit for bit
        x, y = np.asarray(x), np.asarray(y)
        if a is None:
            np.testing.assert_array_equal(x, y)
        else:
            assert x.shape[1:] == y.shape[1:]
            np.testing.assert_array_equal(x[idx], y)
    d = world.pair_id("ball", "dish")
    m = world.mj_models[d]
    np.testing.assert_allclose(m.geom_size[m.geom("obj_base").id], [0.11, 0.11, 0.005])
    np.testing.assert_allclose(m.body_mass[world.obj_body], 0.30, rtol=1e-6)


def _dish_world():
    from relaff_jax.sim import world as wd

    lib.activate(ol.select(ol.load_library(EXAMPLE), ("ball", "block", "toy_can", "dish", "plate")))
    world = wd.build_world()
    assert world.pairs == tuple((t, o, "toy+base") for t in ("ball", "block", "toy_can")  # registry order
                                for o in ("plate", "dish"))
    return world


def test_user_object_scenes_settle_by_the_relation_rule():
    """Toys dropped into the dish by hand settle in MuJoCo C: the ball and the block (centres
    4.5 and 3.5 cm up) inside the 5 cm rim, the toy can (7 cm) on top; beside it on the table,
    beside."""
    from relaff_jax.sim import scenes as sc
    from relaff_jax.sim.native.settle import settle_batch

    world = _dish_world()
    toys = ("ball", "block", "toy_can")
    pair = np.array([world.pair_id(t, "dish") for t in toys] * 2, np.int32)
    qpos0 = np.tile(np.asarray(world.mj_model.qpos0, np.float32), (len(pair), 1))
    tq, oq = world.toy_qpos, world.obj_qpos
    dish_xy = np.array([0.8, 0.2], np.float32)
    for i in range(len(pair)):
        qpos0[i, oq:oq + 3] = (*dish_xy, 0.001)
        beside = i >= 3
        qpos0[i, tq:tq + 3] = (*(dish_xy + (0.0, 0.3 if beside else 0.03)), 0.001 if beside else 0.014)
    scenes = settle_batch(world, pair, qpos0, np.zeros(len(pair), np.int32), SceneConfig(), nthread=1)
    assert np.asarray(scenes.relation).tolist() == [sc.INSIDE, sc.INSIDE, sc.ON_TOP] + [sc.BESIDE] * 3
    assert np.asarray(scenes.at_rest).all()


@pytest.mark.slow
def test_user_object_scenes_sample_and_settle():
    """Scenes with the dish sampled by the placement sampler: stacked ball and block scenes
    aim inside the dish and settle inside it."""
    import jax

    from relaff_jax.sim import scenes as sc
    from relaff_jax.sim.native.settle import settle_batch

    world = _dish_world()
    d = world.pair_id("ball", "dish")
    cfg = SceneConfig(p_stacked=1.0)
    pair = np.array([d, d, d, d, world.pair_id("block", "dish")] * 2, np.int32)
    qpos0, intended = sc.place(world, cfg, jax.random.PRNGKey(0), pair)
    scenes = settle_batch(world, pair, np.asarray(qpos0), np.asarray(intended), cfg, nthread=1)
    rel = np.asarray(scenes.relation)
    assert (np.asarray(intended) == sc.INSIDE).all()  # both toys fit the dish's 20.4 cm floor
    # dropped 4 mm onto the floor, both stay inside: their centres (4.5 and 3.5 cm up) below the 5 cm rim
    assert (rel == sc.INSIDE).all(), rel
    assert np.asarray(scenes.at_rest).all()


@pytest.mark.parametrize("argv", [["generate", "lift", "--samples", "4", "--engine", "native"],
                                  ["reproduce", "--preset", "tiny"]])
def test_commands_that_simulate_refuse_a_bad_library_before_any_work(tmp_path, capsys, argv):
    bad = write(tmp_path, [dish(groups=["base", "rake"])])
    out = tmp_path / "out"
    assert cli.main(argv + ["--out", str(out), "--objects", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "object 'dish': groups ['base', 'rake']: at most one of base, obstacle, rake" in err[0]
    assert not out.exists()


def test_the_module_imports_on_its_own():
    # the config tree imports this module; it once imported the config at its top, a cycle that
    # failed whenever this module was the first one imported
    import subprocess
    import sys
    run = subprocess.run([sys.executable, "-c", "import relaff_jax.sim.object_library"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr.splitlines()[-1:]
