"""The feature chain's culled cast (``render_objects``: only the tiles an object's projected
bounds reach) against casting every pixel of the image: the same features, bit for bit, on
library pairs posed by hand, among them an object cut by the image border and a toy that
hides part of the other object. The full-image reference puts the object pixels in the same
(tile) order before compaction, so slot i gets noise draw i in both."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import relaff_jax  # noqa: F401  (XLA flags before JAX)
from relaff_jax import perception as P
from relaff_jax.config.perception import PerceptionConfig, RHFConfig
from relaff_jax.perception.noise import add_depth_noise
from relaff_jax.perception.pipeline import features_from_voxels
from relaff_jax.perception.raycast import surface_normals
from relaff_jax.perception.render import compact_objects
from relaff_jax.perception.voxels import voxel_downsample

from helpers.scenes import library_scene

CFG = PerceptionConfig(rhf=RHFConfig(chunk=128))  # the stage's camera, tiles and capacities
UP = [1.0, 0.0, 0.0, 0.0]


def full_image_features(scene, key, cfg):
    """Every pixel cast (``render``), object pixels taken in tile order, then the chain."""
    r = P.render(scene, cfg)
    order = np.asarray(P.tile_rays(cfg.camera, cfg.cull.tile)[1]).reshape(-1)  # pixels by tile
    cloud = dict(pixel=jnp.asarray(order, jnp.int32), depth=r["depth"].reshape(-1)[order],
                 points=r["points"][order], seg=r["seg"][order], geom=r["geom"][order])
    pix = compact_objects(cloud, cfg)
    pix["normal"] = surface_normals(scene, pix["points"], pix["geom"])
    pix = add_depth_noise(pix, key, cfg)
    vox = voxel_downsample(pix["points"], pix["normal"], pix["seg"], cfg)
    vox.update(n_pixels=pix["n_pixels"], pixel_overflow=pix["pixel_overflow"], tile_overflow=jnp.bool_(False))
    return features_from_voxels(vox, cfg), r["seg"].reshape(cfg.camera.height, cfg.camera.width)


def border_point(cfg, v_frac=0.7):
    """Where the ray of the image's left-edge pixel column at row v_frac * H meets the table."""
    cam = cfg.camera
    pos, rot = P.camera_frame(cam)
    fx, fy, cx, cy = P.intrinsics(cam)
    d = rot @ np.array([(0.0 - cx) / fx, (v_frac * cam.height - cy) / fy, 1.0])
    return pos + (-pos[2] / d[2]) * d


def scene_of(toy, other, toy_xyz, other_xyz):
    m, d, seg = library_scene(toy, other, [*toy_xyz, *UP], [*other_xyz, *UP])
    return P.scene_from_mujoco(m, d, seg)


def cases():
    bx, by, _ = border_point(CFG)
    cam = np.asarray(CFG.camera.position)
    front = cam + 0.8 * (np.array([0.8, 0.0, 0.03]) - cam)  # on the line of sight to the bowl
    return {
        "apart": ("block", "bowl", (1.0, 0.3, 0.0), (0.8, -0.2, 0.0)),
        "toy hides the other": ("block", "bowl", tuple(front), (0.8, 0.0, 0.0)),
        "other cut by the border": ("ball", "tray", (0.9, 0.0, 0.0), (bx, by, 0.0)),
        "toy cut by the border": ("ball", "tray", (bx, by, 0.0), (0.9, 0.2, 0.0)),
    }


@pytest.mark.slow  # compiles the full 640 x 480 cast and the chain for two pair layouts (~45 s)
@pytest.mark.parametrize("name", list(cases()))
def test_culled_features_equal_the_full_image_cast(name):
    toy, other, txyz, oxyz = cases()[name]
    scene = scene_of(toy, other, txyz, oxyz)
    keys = [jax.random.PRNGKey(s) for s in (3, 11)]
    culled = jax.jit(lambda s, k: P.features(s, k, CFG))
    full = jax.jit(lambda s, k: full_image_features(s, k, CFG))
    for key in keys:
        got = culled(scene, key)
        want, seg = full(scene, key)
        for field in ("pca", "rhf", "unseen", "n_points", "n_pixels", "overflow"):
            np.testing.assert_array_equal(np.asarray(got[field]), np.asarray(want[field]), err_msg=field)
    seg = np.asarray(seg)
    assert not np.asarray(got["unseen"]).any() and not bool(got["overflow"])
    n_act = int(np.asarray(P.active_tiles(scene, CFG)).sum())
    t = CFG.cull.tile
    assert n_act < (CFG.camera.width // t) * (CFG.camera.height // t) // 4  # the cull skipped most tiles
    if "border" in name:  # the object really reaches the image's first column
        label = 2 if name.startswith("other") else 1
        assert (seg[:, 0] == label).any() and (seg[:, 1:] == label).sum() > 10
    if name == "toy hides the other":  # moving the toy away uncovers pixels of the other object
        alone = scene_of(toy, other, (-4.0, 0.0, 0.0), oxyz)
        n_alone = int(np.sum(np.asarray(P.render(alone, CFG)["seg"]) == 2))
        assert n_alone > int(np.asarray(got["n_pixels"])[1]) + 20
