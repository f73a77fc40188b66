"""The dataset -> perception glue: geoms placed by mjx.kinematics on batched models,
`relaff features` and `relaff show` on a small dataset of settled scenes."""
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from relaff_jax import cli, load_dataset
from relaff_jax import data as dataset
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.errors import UserError
from relaff_jax.perception import from_sim as features
from relaff_jax.sim import scenes as sc

from helpers.scenes import scene_rollout_fn

B = 8


def test_scene_geoms_match_mujoco_c(scene_world, settle):
    w = scene_world
    pair = sc.sample_pairs(jax.random.PRNGKey(7), np.arange(w.n_pairs), w, B)
    qpos0, intended = sc.place(w, sc.SceneConfig(), jax.random.PRNGKey(8), pair)
    out = jax.device_get(settle(pair, qpos0, intended))
    size, xpos, xmat = jax.device_get(features.scene_geoms(w, jnp.asarray(pair), jnp.asarray(out.qpos)))
    for i, p in enumerate(np.asarray(pair)):
        m = w.mj_models[int(p)]
        d = mujoco.MjData(m)
        d.qpos[:] = out.qpos[i]
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(size[i], m.geom_size, atol=1e-7)
        np.testing.assert_allclose(xpos[i], d.geom_xpos, atol=1e-5)
        np.testing.assert_allclose(xmat[i].reshape(-1, 9), d.geom_xmat, atol=1e-5)


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory, scene_world, settle):
    path = tmp_path_factory.mktemp("ds") / "lift"
    dataset.generate_dataset(path, "lift", scene_rollout_fn(scene_world, settle), seed=1, progress=False,
                             dataset_config=DatasetConfig(n_samples=8, rollout_batch=B, borrow_fraction=1.0))
    return path


def test_features_command_and_show(small_dataset, tmp_path, capsys):
    assert cli.main(["features", str(small_dataset), "--batch", "4"]) == 0
    ds = load_dataset(small_dataset)
    n = len(ds["label"])
    assert ds["pca"].shape == (n, 18)
    assert ds["rhf"].shape == (n, 300)
    assert ds["unseen"].shape == (n, 2)
    assert np.isfinite(ds["pca"]).all()
    assert np.isfinite(ds["rhf"]).all()
    seen = ~ds["unseen"].any(1)
    assert seen.any()
    np.testing.assert_allclose(ds["rhf"][seen].reshape(-1, 6, 50).sum(-1), 1.0, atol=1e-4)
    # the toy's PCA centroid is where the settled toy is (within the object size)
    w = features.wd.build_world()
    toy_xy = ds["qpos_settled"][:, w.toy_qpos:w.toy_qpos + 2]
    ok = ~ds["unseen"][:, 0]
    assert np.all(np.linalg.norm(ds["pca"][ok, :2] - toy_xy[ok], axis=1) < 0.1)
    # a second run finds the features complete and computes nothing
    assert cli.main(["features", str(small_dataset), "--batch", "4"]) == 0
    capsys.readouterr()
    out = tmp_path / "scene.png"
    assert cli.main(["show", str(small_dataset), "--index", "1", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 10_000
    assert cli.main(["show", str(small_dataset), "--index", "99", "--out", str(out)]) == 2
    assert "out of range" in capsys.readouterr().err


def test_show_checks_out_before_work(small_dataset, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert cli.main(["show", str(small_dataset), "--out", str(blocker / "scene.png")]) == 2
    assert "is a file" in capsys.readouterr().err
    assert cli.main(["show", str(small_dataset), "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_noise_keys_use_all_64_bits_of_the_rollout_id():
    root = jax.random.PRNGKey(3)
    ids = np.array([5, 5 + 2**32, 2**32 - 1, 7 * 2**32 + 5, 0], np.int64)
    keys = np.asarray(features.rollout_keys(root, ids))
    # ids < 2^32: exactly the key of earlier versions, fold_in(root, uint32 id)
    for i in (0, 2, 4):
        np.testing.assert_array_equal(keys[i], jax.random.fold_in(root, np.uint32(ids[i])))
    # ids differing by multiples of 2^32 no longer share a noise stream
    assert len({tuple(k) for k in keys[[0, 1, 3]]}) == 3
    noise = [np.asarray(jax.random.normal(k, (8,))) for k in keys[[0, 1]]]
    assert not np.array_equal(*noise)
    np.testing.assert_array_equal(features.show_key(5), jax.random.PRNGKey(5))
    np.testing.assert_array_equal(features.show_key(2**32 - 1), jax.random.PRNGKey(2**32 - 1))
    assert not np.array_equal(features.show_key(5 + 2**32), jax.random.PRNGKey(5))


def test_features_of_ids_differing_by_2_32_differ(small_dataset, scene_world):
    ds = dataset.load_dataset(small_dataset, features=False)
    fn = features.make_feature_fn(scene_world)
    i = np.zeros(4, int)  # one scene four times (a batch of 4, as the CLI test compiled)
    r = int(ds["rollout_id"][0]) % 2**32
    out = fn({"pair": ds["pair"][i], "qpos_settled": ds["qpos_settled"][i],
              "rollout_id": np.array([r, r + 2**32, r, r + 2**33], np.int64)})
    np.testing.assert_array_equal(out["pca"][0], out["pca"][2])
    assert not np.array_equal(out["pca"][0], out["pca"][1])
    assert not np.array_equal(out["pca"][1], out["pca"][3])


def test_missing_fields_is_a_clear_error(scene_world):
    fn = features.make_feature_fn(scene_world)
    with pytest.raises(UserError, match="lack.*qpos_settled"):
        fn({"pair": np.zeros(2, np.int32), "rollout_id": np.zeros(2)})


def test_voxel_size_set_from_the_cli_changes_the_features(small_dataset, tmp_path):
    """--set reaches the perception config: the voxel size is recorded and changes the features."""
    import json
    import shutil

    assert cli.main(["features", str(small_dataset), "--batch", "4"]) == 0
    other = tmp_path / "lift"
    shutil.copytree(small_dataset, other)
    # features of another config on a featured dataset: refused without --overwrite
    assert cli.main(["features", str(other), "--batch", "4", "--set", "perception.voxel.size=0.025"]) == 2
    assert cli.main(["features", str(other), "--batch", "4", "--set", "perception.voxel.size=0.025",
                     "--overwrite"]) == 0
    a, b = load_dataset(small_dataset), load_dataset(other)
    assert not np.array_equal(a["rhf"], b["rhf"])
    assert not np.array_equal(a["pca"], b["pca"])
    side = json.loads((other / dataset.FEATURES_SIDECAR).read_text())
    assert side["config"]["perception"]["voxel"]["size"] == 0.025
    rec = json.loads((other / "relaff_config.json").read_text())
    assert rec["command"] == "features"
    assert rec["config"]["perception"]["voxel"]["size"] == 0.025
    assert rec["config"]["dataset"]["feature_batch"] == 4


def test_sub_batches_give_the_same_features(small_dataset, scene_world):
    """A chunk perceived in calls of 3 scenes (the last one padded) or of 4 (the default
    ``SUB_BATCH``, one call here) gives the same features, bit for bit (one more compile)."""
    ds = dataset.load_dataset(small_dataset, features=False)
    i = np.arange(4) % len(ds["pair"])
    s = {"pair": ds["pair"][i], "qpos_settled": ds["qpos_settled"][i], "rollout_id": ds["rollout_id"][i]}
    assert features.SUB_BATCH == 4
    want = features.make_feature_fn(scene_world)(s)
    got = features.make_feature_fn(scene_world, sub_batch=3)(s)
    for k in want:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    with pytest.raises(UserError, match="sub_batch"):
        features.make_feature_fn(scene_world, sub_batch=0)


@pytest.mark.slow  # compiles the 640 x 480 chain at the config's capacities and at the buckets used
def test_culled_feature_fn_equals_the_full_capacity_chain(small_dataset, scene_world):
    """The features stage's function (capacities sized per call, RHF tiles of 128) gives the
    bits of every call at the config's capacities (65,536 rays, 32,768 pixel slots, RHF tiles
    of 256) on stored scenes, each at a capacity below the config's."""
    ds = dataset.load_dataset(small_dataset, features=False)
    i = np.arange(8) % len(ds["pair"])
    s = {"pair": ds["pair"][i], "qpos_settled": ds["qpos_settled"][i], "rollout_id": ds["rollout_id"][i]}
    want = features.make_feature_fn(scene_world, culled=False)(s)
    got = features.make_feature_fn(scene_world)(s)
    for k in want:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    assert np.sum(~want["unseen"].any(1)) >= 4 and np.all(want["rhf"][~want["unseen"].any(1)].sum(1) > 5.9)
