"""Perception oracle tests: camera vs MuJoCo mj_multiRay, noise vs its formula, voxels vs
Open3D, PCA vs numpy eigh, RHF vs a plain double loop, batching without retracing.

Small sizes: 160x120 images, batches of 2-3 scenes.
"""
from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from relaff_jax import perception as P
from relaff_jax.config.perception import CameraConfig, CullConfig, PerceptionConfig, RHFConfig, VoxelConfig
from relaff_jax.config import ConfigError, override

from helpers.scenes import library_scene

SMALL = PerceptionConfig(
    camera=CameraConfig(width=160, height=120),
    voxel=VoxelConfig(max_object_pixels=8192, max_voxels=2048),
    rhf=RHFConfig(chunk=128),
    cull=CullConfig(tile=8, max_tiles=300),
)

# ----------------------------------------------------------------------------- scenes

# One layout for every random scene (so a batch shares static geom info):
# plane, toy = sphere + box, other = 3 boxes + capsule, a hidden box (segment -1, alpha 0).
LAYOUT = (
    ("plane", 0), ("sphere", 1), ("box", 1), ("box", 2), ("box", 2), ("box", 2), ("capsule", 2),
    ("box", -1),
)


def random_scene_xml(rng, plane_size="0 0 1") -> str:
    geoms = []
    for kind, seg in LAYOUT:
        if kind == "plane":
            geoms.append(f'<geom type="plane" size="{plane_size}" material="m"/>')
            continue
        x, y = rng.uniform(0.3, 1.5), rng.uniform(-0.8, 0.8)
        z = rng.uniform(0.0, 0.4)
        euler = " ".join(f"{v:.4f}" for v in rng.uniform(-180, 180, 3))
        alpha = 0 if seg < 0 else 1
        if kind == "sphere":
            size = f"{rng.uniform(0.03, 0.12):.4f}"
        elif kind == "capsule":
            size = f"{rng.uniform(0.02, 0.06):.4f} {rng.uniform(0.05, 0.2):.4f}"
        else:
            size = " ".join(f"{v:.4f}" for v in rng.uniform(0.02, 0.2, 3))
        geoms.append(
            f'<body pos="{x:.4f} {y:.4f} {z:.4f}" euler="{euler}">'
            f'<geom type="{kind}" size="{size}" rgba="1 0 0 {alpha}"/></body>'
        )
    return (
        '<mujoco><asset><material name="m" rgba=".5 .5 .5 1"/></asset><worldbody>'
        + "".join(geoms)
        + "</worldbody></mujoco>"
    )


def mj_scene(xml: str):
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return m, d


def stack_scenes(scenes, seg):
    ms = [m for m, _ in scenes]
    return P.make_scene(
        ms[0].geom_type, seg,
        np.stack([m.geom_size for m in ms]),
        np.stack([d.geom_xpos for _, d in scenes]),
        np.stack([d.geom_xmat for _, d in scenes]),
    )


@pytest.fixture(scope="module")
def random_scenes():
    rng = np.random.default_rng(7)
    scenes = [mj_scene(random_scene_xml(rng)) for _ in range(3)]
    seg = np.array([s for _, s in LAYOUT])
    return scenes, seg


_render_small = jax.jit(jax.vmap(lambda s: P.render(s, SMALL)))


@pytest.fixture(scope="module")
def rendered(random_scenes):
    """Full noise-free renders of the random scenes (one compile for every test)."""
    scenes, seg = random_scenes
    return _render_small(stack_scenes(scenes, seg))


@pytest.fixture(scope="module")
def chain(random_scenes):
    """Point clouds and features of the random scenes through ``make_batched_features``,
    instrumented with chex.assert_max_traces (one compile for every test)."""
    scenes, seg = random_scenes
    batch = stack_scenes(scenes, seg)
    keys = jax.random.split(jax.random.key(5), len(scenes))
    f = P.make_batched_features(scenes[0][0].geom_type, seg, SMALL, wrap=chex.assert_max_traces(n=1))
    return dict(f=f, batch=batch, keys=keys, feats=f(batch.size, batch.xpos, batch.xmat, keys))


def mj_reference(m, d, cam: CameraConfig):
    """Native MuJoCo: geom id (P,), depth (P,) (dist along rays whose camera-z is 1), normal."""
    origin, dirs = P.camera_rays(cam)
    n = dirs.shape[0]
    geom = np.zeros(n, np.int32)
    dist = np.zeros(n)
    normal = np.zeros(3 * n)
    mujoco.mj_multiRay(m, d, origin, dirs.ravel().copy(), None, 1, -1, geom, dist, normal, n, 1e6)
    valid = (geom >= 0) & (dist >= cam.near) & (dist <= cam.far)
    return np.where(valid, geom, -1), np.where(valid, dist, 0.0), normal.reshape(n, 3)


# ----------------------------------------------------------------------------- camera


def test_intrinsics_and_pose_follow_robwork():
    cam = CameraConfig()
    fx, fy, cx, cy = P.intrinsics(cam)
    assert fx == pytest.approx(240 / np.tan(np.deg2rad(21.5)))
    assert fx == pytest.approx(609.3, abs=0.05)
    assert fy == fx
    assert (cx, cy) == (320.0, 240.0)
    pos, rot = P.camera_frame(cam)
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0)
    fwd = np.subtract(cam.target, cam.position)
    np.testing.assert_allclose(rot[:, 2], fwd / np.linalg.norm(fwd), atol=1e-12)
    assert rot[2, 1] < 0  # image "down" points down in the world
    _, dirs = P.camera_rays(cam)
    # The optical axis passes between the four centre pixels; every ray has camera z = 1.
    np.testing.assert_allclose(dirs @ rot[:, 2], 1.0, atol=1e-12)
    centre = dirs.reshape(480, 640, 3)[239:241, 319:321].mean(axis=(0, 1))
    np.testing.assert_allclose(centre, rot[:, 2], atol=1e-12)


def test_default_camera_sees_the_workspace():
    """Workspace half-disc x > 0, r <= 1.8 m on the table: most of it is in view."""
    cam = CameraConfig()
    fx, fy, cx, cy = P.intrinsics(cam)
    pos, rot = P.camera_frame(cam)
    r, th = np.meshgrid(np.linspace(0.2, 1.8, 30), np.linspace(-np.pi / 2, np.pi / 2, 60))
    pts = np.stack([r.ravel() * np.cos(th.ravel()), r.ravel() * np.sin(th.ravel()), np.zeros(r.size)], 1)
    pc = (pts - pos) @ rot
    u, v = fx * pc[:, 0] / pc[:, 2] + cx, fy * pc[:, 1] / pc[:, 2] + cy
    inside = (pc[:, 2] > 0) & (u >= 0) & (u < 640) & (v >= 0) & (v < 480)
    assert inside.mean() > 0.85


def test_render_matches_mj_multiray(random_scenes, rendered):
    scenes, seg = random_scenes
    out = rendered
    total_obj = 0
    for b, (m, d) in enumerate(scenes):
        geom_ref, depth_ref, normal_ref = mj_reference(m, d, SMALL.camera)
        geom = np.asarray(out["geom"][b])
        assert np.array_equal(geom, geom_ref), f"scene {b}: {np.sum(geom != geom_ref)} pixels differ"
        seg_ref = np.where(geom_ref >= 0, seg[np.maximum(geom_ref, 0)], -1)
        assert np.array_equal(np.asarray(out["seg"][b]), seg_ref)
        depth = np.asarray(out["depth"][b]).ravel()
        assert np.abs(depth - depth_ref).max() < 1e-4
        hit = geom >= 0
        assert np.abs(np.asarray(out["normal"][b])[hit] - normal_ref[hit]).max() < 1e-3
        # points = camera centre + depth * ray, in the robot frame
        origin, dirs = P.camera_rays(SMALL.camera)
        pts_ref = origin + depth_ref[:, None] * dirs
        assert np.abs(np.asarray(out["points"][b])[hit] - pts_ref[hit]).max() < 1e-4
        total_obj += np.sum(np.isin(seg_ref, (1, 2)))
        assert np.sum(geom_ref == len(LAYOUT) - 1) == 0  # the hidden geom never shows
    assert total_obj > 300  # the scenes do show objects


def test_finite_plane_and_far_clip_match_mujoco():
    rng = np.random.default_rng(3)
    m, d = mj_scene(random_scene_xml(rng, plane_size="1.2 0.7 0.1"))
    seg = np.array([s for _, s in LAYOUT])
    cfg = override(SMALL, {"camera.far": 4.0})
    out = jax.jit(lambda s: P.render(s, cfg))(P.scene_from_mujoco(m, d, seg))
    geom_ref, depth_ref, _ = mj_reference(m, d, cfg.camera)
    assert np.array_equal(np.asarray(out["geom"]), geom_ref)
    assert np.abs(np.asarray(out["depth"]).ravel() - depth_ref).max() < 1e-4
    assert np.sum(geom_ref == -1) > 1000  # past the plane's edge or beyond far: no point


def test_render_objects_equals_full_render(random_scenes, rendered):
    scenes, seg = random_scenes
    batch = stack_scenes(scenes, seg)
    full = rendered
    cfg = override(SMALL, {"cull.max_tiles": 120})
    part = jax.jit(jax.vmap(lambda s: P.render_objects(s, cfg)))(batch)
    n_active = np.asarray(jax.vmap(lambda s: P.active_tiles(s, cfg))(batch)).sum(1)
    assert np.all(n_active < 120)
    assert np.all(n_active > 5)
    for b in range(len(scenes)):
        assert not bool(part["tile_overflow"][b])
        seg_full = np.asarray(full["seg"][b])
        obj_full = np.flatnonzero(np.isin(seg_full, (1, 2)))
        pix = np.asarray(part["pixel"][b])
        seg_part = np.asarray(part["seg"][b])
        keep = np.isin(seg_part, (1, 2))
        order = np.argsort(pix[keep])
        assert np.array_equal(pix[keep][order], obj_full)
        assert np.array_equal(seg_part[keep][order], seg_full[obj_full])
        np.testing.assert_array_equal(np.asarray(part["points"][b])[keep][order],
                                      np.asarray(full["points"][b])[obj_full])


# ----------------------------------------------------------------------------- noise


def test_robwork_sigma_hand_worked():
    cam = CameraConfig()
    # Pixel (row 239, col 319) has r = sqrt(0.5^2 + 0.5^2) px; d = 3000 mm.
    r = np.hypot(0.5, 0.5)
    d = 3000.0
    s_mm = (2.344 - 1.202e-2 * r - 1.734e-3 * d + 1.818e-5 * r * r + 6.516e-6 * r * d + 1.233e-6 * d * d)
    got = P.depth_noise_sigma(jnp.float32(3.0), jnp.int32(239 * 640 + 319), cam, "robwork")
    assert float(got) == pytest.approx(s_mm / 1000, rel=1e-5)
    assert float(P.depth_noise_sigma(jnp.float32(2.0), jnp.int32(0), cam, "khoshelham")) == pytest.approx(1.425e-3 * 4)
    assert float(P.depth_noise_sigma(jnp.float32(1.4), jnp.int32(0), cam, "nguyen")) == pytest.approx(0.0012 + 0.0019)
    # r is measured in 640-wide pixels at any resolution: a 160x120 pixel centre at
    # (u + 0.5, v + 0.5) is 4x farther out in 640-pixel units.
    small = CameraConfig(width=160, height=120)
    u, v = 20, 10
    r_small = float(P.pixel_radius(jnp.int32(v * 160 + u), small))
    assert r_small == pytest.approx(np.hypot(4 * (u + 0.5) - 320, 4 * (v + 0.5) - 240), rel=1e-6)


@pytest.mark.parametrize("model", ["robwork", "khoshelham", "nguyen"])
def test_noise_empirical_std_matches_formula(rendered, model):
    cfg = override(SMALL, {"noise.model": model})
    clean = jax.tree.map(lambda x: x[0], rendered)
    keys = jax.random.split(jax.random.key(11), 64)
    noisy = jax.jit(jax.vmap(lambda k: P.add_depth_noise(clean, k, cfg)))(keys)
    valid = np.asarray(clean["seg"]) >= 0
    pix = np.flatnonzero(valid)
    sigma = np.asarray(P.depth_noise_sigma(clean["depth"].reshape(-1), jnp.arange(valid.size), cfg.camera, model))
    dz = np.asarray(noisy["depth"]).reshape(64, -1) - np.asarray(clean["depth"]).reshape(-1)
    z = dz[:, pix] / sigma[pix]
    assert abs(z.mean()) < 0.01
    assert z.std() == pytest.approx(1.0, abs=0.01)
    # Invalid pixels untouched; the point moves along the optical axis by exactly dz.
    assert np.all(dz[:, ~valid] == 0)
    fwd = P.camera_frame(cfg.camera)[1][:, 2]
    shift = np.asarray(noisy["points"][0]) - np.asarray(clean["points"])
    np.testing.assert_allclose(shift[pix], dz[0, pix, None] * fwd, atol=2e-6)


# ----------------------------------------------------------------------------- voxels


def open3d_voxels(points: np.ndarray, normals: np.ndarray, size: float):
    import open3d as o3d

    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(points.astype(np.float64))
    pc.normals = o3d.utility.Vector3dVector(normals.astype(np.float64))
    down = pc.voxel_down_sample(size)
    return np.asarray(down.points), np.asarray(down.normals)


def _lexsorted(a):
    return a[np.lexsort(a.T[::-1])]


def _unambiguous(points, seg, size):
    """seg with points that sit within float32 reach of a voxel boundary relabelled 0
    (ignored): our float32 index may legitimately differ from Open3D's float64 one there.
    float32 error of (p - origin) / size is ~1e-5 voxel units at 1 m; 5e-5 is the margin."""
    seg = seg.copy()
    dropped = 0
    for s_ in (1, 2):
        sel = np.flatnonzero(seg == s_)
        if not len(sel):
            continue
        p = points[sel].astype(np.float64)
        ref = (p - (p.min(0) - size / 2)) / size
        amb = (np.abs(ref - np.round(ref)) < 5e-5).any(1)
        seg[sel[amb]] = 0
        dropped += int(amb.sum())
    return seg, dropped


def test_voxels_match_open3d(random_scenes):
    scenes, seg = random_scenes
    size = SMALL.voxel.size
    vox_fn = jax.jit(lambda p, q, s: P.voxel_downsample(p, q, s, SMALL))
    checked = dropped_total = total = 0
    for b, (m, d) in enumerate(scenes):
        # Unbatched chain (scene_view, also used by the picture test: one compile).
        view = P.scene_view(P.scene_from_mujoco(m, d, seg), jax.random.key(b), SMALL)
        pix = view["pixels"]
        # The chain's voxels are voxel_downsample of its (noisy) object pixels.
        again = vox_fn(pix["points"], pix["normal"], pix["seg"])
        np.testing.assert_array_equal(np.asarray(again["points"]), view["voxels"]["points"])
        np.testing.assert_array_equal(view["feats"]["n_points"], view["voxels"]["count"])
        seg_ok, dropped = _unambiguous(pix["points"], pix["seg"], size)
        dropped_total += dropped
        vox = jax.tree.map(np.asarray, vox_fn(pix["points"], pix["normal"], seg_ok))
        for o, s in enumerate((1, 2)):
            sel = seg_ok == s
            pts, nrm = pix["points"][sel], pix["normal"][sel]
            total += len(pts)
            n = int(vox["count"][o])
            if len(pts) == 0:
                assert n == 0
                continue
            o3_p, o3_n = open3d_voxels(pts, nrm, size)
            assert n == len(o3_p)
            assert not vox["voxel_overflow"][o]
            mine = vox["points"][o][:n]
            assert vox["mask"][o][:n].all()
            assert not vox["mask"][o][n:].any()
            np.testing.assert_allclose(_lexsorted(mine), _lexsorted(o3_p), atol=2e-6)
            # normals: Open3D keeps the unnormalised mean; we normalise it
            o3_n = o3_n / np.linalg.norm(o3_n, axis=1, keepdims=True)
            order_m, order_o = np.lexsort(mine.T[::-1]), np.lexsort(o3_p.T[::-1])
            np.testing.assert_allclose(vox["normals"][o][:n][order_m], o3_n[order_o], atol=1e-4)
            checked += 1
    assert checked >= 4
    assert dropped_total <= 0.01 * total


def test_voxels_open3d_random_cloud():
    """A plain random cloud (not from the camera), both segments, many points per voxel."""
    rng = np.random.default_rng(1)
    n = 3000
    pts = np.concatenate([rng.normal([1.0, 0.2, 0.1], 0.03, (n, 3)), rng.uniform([0.5, -0.4, 0], [0.8, -0.1, 0.2], (n, 3))])
    pts = pts.astype(np.float32)
    nrm = rng.normal(size=pts.shape).astype(np.float32)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    seg = np.repeat(np.int32([1, 2]), n)
    seg[::97] = 0  # some table points: ignored
    seg, dropped = _unambiguous(pts, seg, 0.0125)
    assert dropped < 10
    cfg = override(SMALL, {"voxel.max_voxels": 8192, "rhf.chunk": 128})
    vox = jax.jit(lambda p, q, s: P.voxel_downsample(p, q, s, cfg))(pts, nrm, seg)
    for o, s in enumerate((1, 2)):
        sel = seg == s
        o3_p, _ = open3d_voxels(pts[sel], nrm[sel], 0.0125)
        k = int(vox["count"][o])
        assert k == len(o3_p)
        np.testing.assert_allclose(_lexsorted(np.asarray(vox["points"][o][:k])), _lexsorted(o3_p), atol=2e-6)


@pytest.mark.slow  # compiles the chain at small capacities
def test_voxel_and_pixel_overflow_are_flagged_not_silent(chain):
    ok = chain["feats"]
    assert not bool(jnp.any(ok["overflow"]))
    n_pix = np.asarray(ok["n_pixels"]).sum(1)
    n_vox = np.asarray(ok["n_points"])
    n_tiles = np.asarray(jax.vmap(lambda s: P.active_tiles(s, SMALL))(chain["batch"])).sum(1)
    # Capacities between the scenes' sizes: some scenes overflow, some do not.
    m_cap = int(np.sort(n_pix)[1])
    t_cap = int(np.sort(n_tiles)[-1]) - 1  # only the scene with the most active tiles
    cfg = override(SMALL, {"voxel.max_voxels": 128, "voxel.max_object_pixels": m_cap,
                           "rhf.chunk": 64, "cull.max_tiles": t_cap})
    out = jax.jit(jax.vmap(lambda s, k: P.features(s, k, cfg)))(chain["batch"], chain["keys"])
    np.testing.assert_array_equal(np.asarray(out["tile_overflow"]), n_tiles > t_cap)
    tiles_fit = ~np.asarray(out["tile_overflow"])
    np.testing.assert_array_equal(np.asarray(out["pixel_overflow"])[tiles_fit], (n_pix > m_cap)[tiles_fit])
    assert bool(jnp.any(out["pixel_overflow"]))
    assert not bool(jnp.all(out["pixel_overflow"]))
    fits = ~np.asarray(out["pixel_overflow"]) & tiles_fit
    assert fits.any()
    # Where the pixels fit, voxel counts are the true ones and overflow is flagged past 128.
    np.testing.assert_array_equal(np.asarray(out["n_points"])[fits], n_vox[fits])
    np.testing.assert_array_equal(np.asarray(out["voxel_overflow"])[fits], n_vox[fits] > 128)
    assert bool(jnp.any(out["voxel_overflow"]))
    np.testing.assert_array_equal(
        np.asarray(out["overflow"]),
        np.asarray(out["pixel_overflow"] | jnp.any(out["voxel_overflow"], 1) | out["tile_overflow"]),
    )
    assert all(bool(jnp.all(jnp.isfinite(out[k]))) for k in ("pca", "rhf"))


# ----------------------------------------------------------------------------- PCA


def numpy_pca(points: np.ndarray):
    """Independent reference: numpy eigh + the documented sign rule and ZYX angles."""
    p = points.astype(np.float64)
    mu = p.mean(0)
    cov = (p - mu).T @ (p - mu) / len(p)
    w, v = np.linalg.eigh(cov)

    def fix(vec, order):
        for i in order:
            if abs(vec[i]) > 1e-6:
                return vec * np.sign(vec[i])
        return vec

    x, z = fix(v[:, 2], (0, 1, 2)), fix(v[:, 0], (2, 0, 1))
    rot = np.stack([x, np.cross(z, x), z], axis=1)
    yaw = np.arctan2(rot[1, 0], rot[0, 0])
    pitch = np.arctan2(-rot[2, 0], np.hypot(rot[0, 0], rot[1, 0]))
    roll = np.arctan2(rot[2, 1], rot[2, 2])
    return np.concatenate([mu, [roll, pitch, yaw], w[::-1]]), rot


def box_cloud(rng, extents, n=2000):
    return rng.uniform(-0.5, 0.5, (n, 3)) * np.asarray(extents)


def rot_zyx(yaw, pitch, roll):
    cz, sz, cy, sy, cx, sx = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return rz @ ry @ rx


@pytest.mark.parametrize("yaw_deg", [-80.0, -30.0, 0.0, 25.0, 60.0, 89.0])
def test_pca_elongated_box_returns_its_yaw(yaw_deg):
    rng = np.random.default_rng(int(yaw_deg) + 100)
    yaw = np.deg2rad(yaw_deg)
    pts = box_cloud(rng, (0.40, 0.12, 0.03)) @ rot_zyx(yaw, 0, 0).T + [1.1, -0.3, 0.05]
    V = 2048
    buf = np.zeros((V, 3), np.float32)
    buf[: len(pts)] = pts
    mask = np.arange(V) < len(pts)
    feats, unseen = jax.jit(lambda p, m: P.pca_object(p, m, 10))(buf, mask)
    feats = np.asarray(feats)
    assert not bool(unseen)
    ref, _ = numpy_pca(pts.astype(np.float32))
    np.testing.assert_allclose(feats, ref, atol=2e-5, rtol=1e-4)
    assert feats[5] == pytest.approx(yaw, abs=0.02)  # the yaw we put in
    assert abs(feats[3]) < 0.02
    assert abs(feats[4]) < 0.02
    np.testing.assert_allclose(feats[:3], [1.1, -0.3, 0.05], atol=0.01)
    # eigenvalues of a uniform box: extent^2 / 12, largest first
    np.testing.assert_allclose(feats[6:], np.array([0.40, 0.12, 0.03]) ** 2 / 12, rtol=0.1)


def test_pca_yaw_range_is_half_circle_and_frame_right_handed():
    rng = np.random.default_rng(0)
    pts = box_cloud(rng, (0.5, 0.1, 0.02)) @ rot_zyx(np.deg2rad(120), 0, 0).T
    mu, frame, evals = jax.jit(P.pca_frame)(jnp.asarray(pts, jnp.float32), jnp.ones(len(pts), bool))
    frame = np.asarray(frame)
    assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-5)
    assert frame[0, 0] > 0
    assert frame[2, 2] > 0  # x towards +x (away from the robot), z up
    yaw = float(P.rotation_to_rpy(jnp.asarray(frame))[2])
    assert yaw == pytest.approx(np.deg2rad(120 - 180), abs=0.02)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pca_tilted_boxes_match_numpy(seed):
    rng = np.random.default_rng(seed)
    angles = rng.uniform(-1.2, 1.2, 3)
    pts = box_cloud(rng, (0.3, 0.15, 0.05), 1500) @ rot_zyx(*angles).T + rng.uniform(0, 1, 3)
    feats, _ = P.pca_object(jnp.asarray(pts, jnp.float32), jnp.ones(len(pts), bool), 10)
    ref, _ = numpy_pca(pts.astype(np.float32))
    np.testing.assert_allclose(np.asarray(feats), ref, atol=5e-5, rtol=1e-4)


def test_pca_unseen_below_min_points_is_zero_not_nan():
    pts = jnp.zeros((64, 3)).at[:4].set(jnp.array([[1.0, 0, 0], [1.1, 0, 0], [1.0, 0.1, 0], [1.0, 0, 0.1]]))
    for n in (0, 1, 4):
        feats, unseen = P.pca_object(pts, jnp.arange(64) < n, 10)
        assert bool(unseen)
        np.testing.assert_array_equal(np.asarray(feats), 0.0)
    feats, unseen = P.pca_object(pts, jnp.arange(64) < 4, 3)
    assert not bool(unseen)
    assert bool(jnp.all(jnp.isfinite(feats)))


# ----------------------------------------------------------------------------- RHF


def numpy_rhf_loop(pa, na, pb, nb, rcfg):
    """Plain double loop in float64: the documented six values and bins.

    Returns histograms (6, bins) summing to 1 each and, per feature, the number of pairs whose
    value lies within 1e-5 of a bin edge (float32 may put those in the neighbouring bin)."""
    nbin = rcfg.bins
    hist = np.zeros((6, nbin))
    ambiguous = np.zeros(6, int)
    for a, n_a in zip(pa.astype(np.float64), na.astype(np.float64)):
        for b, n_b in zip(pb.astype(np.float64), nb.astype(np.float64)):
            d = b - a
            dist = np.sqrt(d @ d)
            ang_nn = np.arccos(np.clip(n_a @ n_b, -1, 1))
            ang_nd = np.arccos(np.clip(n_a @ d / dist, -1, 1)) if dist > 0 else 0.0
            for f, v in enumerate((d[0], d[1], d[2], dist, ang_nn, ang_nd)):
                lo, hi = rcfg.ranges[f]
                x = (v - lo) / (hi - lo) * nbin
                hist[f, min(max(int(np.floor(x)), 0), nbin - 1)] += 1
                if 0 < x < nbin and abs(x - np.round(x)) < 1e-5 * nbin:
                    ambiguous[f] += 1
    return hist / (len(pa) * len(pb)), ambiguous


def _random_cloud(rng, n, centre, spread):
    p = rng.normal(centre, spread, (n, 3)).astype(np.float32)
    q = rng.normal(size=(n, 3)).astype(np.float32)
    return p, q / np.linalg.norm(q, axis=1, keepdims=True)


@pytest.mark.parametrize("na_pts,nb_pts,chunk", [(37, 53, 16), (5, 130, 32), (64, 64, 64)])
def test_rhf_matches_numpy_double_loop(na_pts, nb_pts, chunk):
    rng = np.random.default_rng(na_pts * 1000 + nb_pts)
    pa, qa = _random_cloud(rng, na_pts, [1.0, 0.1, 0.05], 0.08)
    pb, qb = _random_cloud(rng, nb_pts, [1.1, 0.0, 0.1], 0.2)  # some values beyond the ranges
    rcfg = RHFConfig(chunk=chunk)
    V = 256
    pad = lambda x: np.concatenate([x, np.full((V - len(x), 3), 7.0, np.float32)])  # junk past count
    got = jax.jit(lambda *a: P.rhf_histograms(*a, rcfg))(pad(pa), pad(qa), na_pts, pad(pb), pad(qb), nb_pts)
    got = np.asarray(got).reshape(6, rcfg.bins)
    ref, ambiguous = numpy_rhf_loop(pa, qa, pb, qb, rcfg)
    np.testing.assert_allclose(got.sum(1), 1.0, atol=1e-6)
    diff_pairs = np.abs(got - ref).sum(1) * na_pts * nb_pts / 2  # pairs in a different bin
    assert np.all(diff_pairs <= ambiguous + 1e-3), (diff_pairs, ambiguous)
    assert ref[:, 0].sum() + ref[:, -1].sum() > 0  # clipping into the end bins was exercised


def test_rhf_hand_worked_pair():
    """One pair: a at the origin with n_a = +z; b at (0.11, 0.013, 0.065) with n_b 60 deg from +z.

    dx = 0.11 in [-0.5 - 1/150, 0.5 - 1/150]: (0.11 + 0.506667) * 50 = 30.83 -> bin 30;
    dy = 0.013: 25.98 -> 25; dz = 0.065 in [-0.25 - 1/300, 0.25 - 1/300]: 31.83 -> 31;
    |d| = 0.128429 in [0, 0.75]: 8.56 -> 8;
    angles in [-pi/300, 299 pi/300]: angle(n_a, n_b) = 60 deg: (1/3 + 1/300) * 50 = 16.83 -> 16;
    angle(n_a, d) = acos(0.065 / 0.128429) = 59.60 deg: (0.33108 + 1/300) * 50 = 16.72 -> 16."""
    rcfg = RHFConfig(chunk=8)
    pa = np.zeros((8, 3), np.float32)
    na = np.zeros((8, 3), np.float32)
    na[0] = [0, 0, 1]
    pb = np.zeros((8, 3), np.float32)
    pb[0] = [0.11, 0.013, 0.065]
    nb = np.zeros((8, 3), np.float32)
    nb[0] = [np.sin(np.pi / 3), 0, np.cos(np.pi / 3)]
    h = np.asarray(P.rhf_histograms(pa, na, 1, pb, nb, 1, rcfg)).reshape(6, 50)
    assert [int(np.argmax(row)) for row in h] == [30, 25, 31, 8, 16, 16]
    np.testing.assert_array_equal(h.sum(1), 1.0)
    empty = P.rhf_histograms(pa, na, 0, pb, nb, 1, rcfg)
    np.testing.assert_array_equal(np.asarray(empty), 0.0)


def test_rhf_exact_common_angles_are_off_bin_edges():
    """Top face (+z) against side faces (+x, -y), another top face and a box-edge voxel's mean
    normal (45 deg): 90, 90, 0, 45 deg exactly, each 1/6 bin or more from an edge."""
    rcfg = RHFConfig(chunk=8)
    pa = np.zeros((8, 3), np.float32)
    na = np.tile(np.float32([0, 0, 1]), (8, 1))
    pb = np.zeros((8, 3), np.float32)
    pb[:4] = [[0.2, 0.03, 0.0], [0.1, -0.2, 0.01], [0.05, 0.05, 0.0], [0.0, 0.1, 0.0]]
    nb = np.zeros((8, 3), np.float32)
    nb[:4] = [[1, 0, 0], [0, -1, 0], [0, 0, 1], [np.sqrt(0.5), 0, np.sqrt(0.5)]]
    h = np.asarray(P.rhf_histograms(pa, na, 1, pb, nb, 4, rcfg)).reshape(6, 50)
    lo, hi = rcfg.ranges[4]
    for deg in (0, 30, 45, 60, 90):
        x = (np.deg2rad(deg) - lo) / (hi - lo) * 50
        assert abs(x - np.round(x)) >= 1 / 6 - 1e-9
    for f in (0, 1, 2):  # whole-millimetre offsets stay >= 1/3 mm from a dx/dy/dz bin edge
        lo, hi = rcfg.ranges[f]
        edges = lo + (hi - lo) / 50 * np.arange(51)
        mm = np.arange(-600, 601) / 1000
        assert np.abs(mm[:, None] - edges[None, :]).min() > 0.00033
    np.testing.assert_allclose(h[4, [0, 12, 25]], [1 / 4, 1 / 4, 2 / 4], atol=1e-6)


# ----------------------------------------------------------------------------- whole chain


def test_features_batched_no_retrace_and_sane(random_scenes, chain):
    scenes, seg = random_scenes
    f = chain["f"]  # its single-scene function is wrapped in chex.assert_max_traces(n=1)
    o1 = chain["feats"]
    b2 = stack_scenes(scenes[::-1], seg)
    o2 = f(b2.size, b2.xpos, np.asarray(b2.xmat).reshape(len(scenes), -1, 9), chain["keys"])
    assert f.jitted._cache_size() == 1  # a second batch of the same shape did not retrace
    for o in (o1, o2):
        B = len(scenes)
        assert o["pca"].shape == (B, 18)
        assert o["rhf"].shape == (B, 300)
        assert o["unseen"].shape == (B, 2)
        assert bool(jnp.all(jnp.isfinite(o["pca"])))
        assert bool(jnp.all(jnp.isfinite(o["rhf"])))
        sums = np.asarray(o["rhf"]).reshape(B, 6, 50).sum(-1)
        seen = ~np.asarray(o["unseen"]).any(1)
        assert seen.any()
        np.testing.assert_allclose(sums[seen], 1.0, atol=1e-5)
        np.testing.assert_array_equal(sums[~seen], 0.0)
    # The features are a per-scene function: the reversed batch gives the reversed rows
    # (the keys were not reversed, so compare the noise-free parts: pixel counts).
    np.testing.assert_array_equal(np.asarray(o2["n_pixels"]), np.asarray(o1["n_pixels"])[::-1])
    # same key, same scene: bit-identical
    again = f(chain["batch"].size, chain["batch"].xpos, chain["batch"].xmat, chain["keys"])
    for k in o1:
        np.testing.assert_array_equal(np.asarray(o1[k]), np.asarray(again[k]))


@pytest.fixture(scope="module")
def library_features():
    """The real geom layout (world.pair_xml: collapsed geoms, finite table plane), 320x240:
    scene 0 a ball beside a bowl, scene 1 a block out of view and a tray."""
    s0 = library_scene("ball", "bowl", [1.0, 0.35, 0.0, 1, 0, 0, 0],
                        [1.0, -0.1, 0.0, np.cos(0.3), 0, 0, np.sin(0.3)])
    s1 = library_scene("block", "tray", [-4.0, 0.0, 0.0, 1, 0, 0, 0], [1.0, 0.0, 0.0, 1, 0, 0, 0])
    cfg = override(PerceptionConfig(), {"camera.width": 320, "camera.height": 240})
    f = P.make_batched_features(s0[0].geom_type, s0[2], cfg)
    size = np.stack([m.geom_size for m, _, _ in (s0, s1)])
    xpos = np.stack([d.geom_xpos for _, d, _ in (s0, s1)])
    xmat = np.stack([d.geom_xmat for _, d, _ in (s0, s1)])
    return jax.tree.map(np.asarray, f(size, xpos, xmat, jax.random.split(jax.random.key(0), 2)))


def test_features_of_library_pair_find_the_objects(library_features):
    out = jax.tree.map(lambda x: x[0], library_features)
    pca = out["pca"]
    assert not out["unseen"].any()
    assert not out["overflow"]
    # Centroids of what the camera sees: near the ball's centre / the bowl, on the camera side.
    assert np.linalg.norm(pca[:3] - [1.0, 0.35, 0.035]) < 0.03
    assert np.linalg.norm(pca[9:11] - [1.0, -0.1]) < 0.06
    assert 0.0 < pca[11] < 0.07
    np.testing.assert_allclose(out["rhf"].reshape(6, 50).sum(1), 1.0, atol=1e-5)


def test_unseen_object_gets_flag_and_zero_features(library_features):
    out = jax.tree.map(lambda x: x[1], library_features)
    np.testing.assert_array_equal(out["unseen"], [True, False])
    assert out["n_pixels"][0] == 0
    assert out["n_points"][0] == 0
    np.testing.assert_array_equal(out["pca"][:9], 0.0)
    assert np.all(out["pca"][9:12] != 0)
    np.testing.assert_array_equal(out["rhf"], 0.0)
    assert not np.any(np.isnan(out["pca"]))
    assert not out["overflow"]


# ----------------------------------------------------------------------------- errors


def test_bad_inputs_raise_clear_errors():
    with pytest.raises(ValueError, match="noise.model"):
        override(SMALL, {"noise.model": "perlin"})
    with pytest.raises(ValueError, match="multiple of rhf.chunk"):
        override(SMALL, {"rhf.chunk": 100})
    with pytest.raises(ValueError, match="cull.tile"):
        override(SMALL, {"cull.tile": 7})
    with pytest.raises(ConfigError):
        override(SMALL, {"camera.fov": 50})
    with pytest.raises(ValueError, match="geom 1: mjtGeom 5"):
        P.make_scene([0, 5], [0, 1], np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 9)))
    with pytest.raises(ValueError, match="segment label 3"):
        P.make_scene([0, 6], [0, 3], np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 9)))
    with pytest.raises(ValueError, match=r"expected size/xpos"):
        P.make_scene([0, 6], [0, 1], np.zeros((3, 3)), np.zeros((2, 3)), np.zeros((2, 9)))
    f = P.make_batched_features([0, 6], [0, 1], SMALL)
    with pytest.raises(ValueError, match=r"expected size and xpos \(B, 2, 3\)"):
        f(np.zeros((2, 2, 3)), np.zeros((2, 3, 3)), np.zeros((2, 2, 9)), jax.random.split(jax.random.key(0), 2))
    with pytest.raises(ValueError, match="one PRNG key per scene"):
        f(np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), np.zeros((2, 2, 9)), jax.random.split(jax.random.key(0), 3))
    assert override(SMALL, {}) == SMALL  # built, so checked


def test_render_scene_png_writes_a_picture(tmp_path, random_scenes):
    scenes, seg = random_scenes
    m, d = scenes[0]
    out = tmp_path / "scene.png"
    v = P.render_scene_png(P.scene_from_mujoco(m, d, seg), jax.random.key(0), out, SMALL, title="test")
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 10_000
    assert v["depth"].shape == (120, 160)
    assert v["seg"].shape == (120, 160)
    assert set(np.unique(v["seg"])) <= {-1, 0, 1, 2}


def test_object_crop_window():
    seg = np.zeros((120, 160), np.int32)
    assert P.object_crop(seg) is None
    seg[50:60, 70:90] = 1
    seg[58:64, 95:100] = 2
    r0, r1, c0, c1 = P.object_crop(seg, margin=0.25, min_margin=8)
    m = int(np.ceil(0.25 * 29))  # 25 % of the larger side of the box (rows 50-63, cols 70-99)
    assert (r0, r1, c0, c1) == (50 - m, 64 + m, 70 - m, 100 + m)
    seg[:] = 0
    seg[0:3, 0:3] = 2  # clipped at the image border
    assert P.object_crop(seg) == (0, 11, 0, 11)


def test_library_never_changes_the_matplotlib_backend(tmp_path, random_scenes):
    """Importing the package or drawing a scene keeps a notebook's backend (no pyplot)."""
    import subprocess
    import sys

    import matplotlib

    code = ("import matplotlib; matplotlib.use('svg'); import relaff_jax.perception, "
            "relaff_jax.perception.plots, relaff_jax.perception.from_sim; "
            "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()")
    subprocess.run([sys.executable, "-c", code], check=True)
    before = matplotlib.get_backend()
    matplotlib.use("pdf")
    try:
        scenes, seg = random_scenes
        m, d = scenes[0]
        P.render_scene_png(P.scene_from_mujoco(m, d, seg), jax.random.key(0), tmp_path / "s.png", SMALL)
        assert matplotlib.get_backend() == "pdf"
    finally:
        matplotlib.use(before)


def test_culled_features_equal_the_batched_chain(chain, random_scenes):
    """``make_culled_features`` (capacities sized per call) gives the bits of
    ``make_batched_features``: buckets put the three scenes at three capacities (the last at
    the config's), pixel buffers shorter than the config's included."""
    scenes, seg = random_scenes
    b = chain["batch"]
    n = np.asarray(P.make_tile_counter(scenes[0][0].geom_type, seg, SMALL)(b.size, b.xpos, b.xmat))
    assert n.max() < SMALL.cull.max_tiles
    buckets = tuple(int(x) for x in np.sort(n)[:2])
    assert buckets[0] < buckets[1]  # three different capacities
    f = P.make_culled_features(scenes[0][0].geom_type, seg, SMALL, sub_batch=1, buckets=buckets)
    got = f(b.size, b.xpos, b.xmat, chain["keys"])
    assert sorted(f.capacities) == [*buckets, SMALL.cull.max_tiles]
    assert P.capacity_config(SMALL, buckets[0]).voxel.max_object_pixels < SMALL.voxel.max_object_pixels
    for k, want in chain["feats"].items():
        np.testing.assert_array_equal(got[k], np.asarray(want), err_msg=k)
    assert not np.all(got["rhf"] == 0)


def test_culled_features_on_pixel_buffers_cut_to_the_cast(chain, random_scenes):
    """The stages after the cast on buffers cut to the object pixels (one bucket: the largest
    scene's count, so that scene's buffer holds exactly its pixels and the others' are shorter
    than their cast's) give the bits of ``make_batched_features``."""
    scenes, seg = random_scenes
    b = chain["batch"]
    counts = np.asarray(chain["feats"]["n_pixels"]).sum(1)
    assert 0 < counts.min() < counts.max() < SMALL.voxel.max_object_pixels
    f = P.make_culled_features(scenes[0][0].geom_type, seg, SMALL, sub_batch=1, buckets=(),
                               pixel_buckets=(int(counts.max()),))
    got = f(b.size, b.xpos, b.xmat, chain["keys"])
    assert sorted(f.pixel_capacities) == [int(counts.max())]
    for k, want in chain["feats"].items():
        np.testing.assert_array_equal(got[k], np.asarray(want), err_msg=k)


def test_warmups_compile_the_programs_the_chain_then_runs(chain, random_scenes):
    """``culled.warmups`` traces and compiles, on placeholder scenes, the cast and the stages
    after it at the capacities given; a ``make_culled_features`` of the same layout, config and
    options then runs those very programs (no new trace) and gives the bits of
    ``make_batched_features``."""
    from relaff_jax.perception import culled

    scenes, seg = random_scenes
    b = chain["batch"]
    gt = scenes[0][0].geom_type
    n = np.asarray(P.make_tile_counter(gt, seg, SMALL)(b.size, b.xpos, b.xmat))
    tiles, pixels = (int(n.max()),), (int(np.asarray(chain["feats"]["n_pixels"]).sum(1).max()),)
    assert tiles[0] < SMALL.cull.max_tiles and pixels[0] < min(SMALL.voxel.max_object_pixels, tiles[0] * SMALL.cull.tile ** 2)
    options = {"xla_cpu_use_fusion_emitters": True, "xla_cpu_enable_fast_min_max": False}  # a key of this test's own
    fns = culled.warmups(gt, seg, SMALL, sub_batch=1, buckets=tiles, pixel_buckets=pixels, compiler_options=options)
    assert len(fns) == 2
    for fn in fns:
        fn()
    store = culled._programs(culled._layout(gt, seg), SMALL, culled._options(options))
    warmed = [store.casts[tiles[0]], store.rests[pixels[0]]]
    assert [p._cache_size() for p in warmed] == [1, 1]  # traced and compiled by the warm-ups themselves
    f = P.make_culled_features(gt, seg, SMALL, sub_batch=1, buckets=tiles, pixel_buckets=pixels, compiler_options=options)
    keys = jax.random.key_data(chain["keys"])  # raw uint32 keys, as the features stage makes them (from_sim.rollout_keys)
    got = f(b.size, b.xpos, b.xmat, keys)
    assert sorted(f.capacities) == list(tiles) and sorted(f.pixel_capacities) == list(pixels)
    assert [*f.capacities.values(), *f.pixel_capacities.values()] == warmed  # the very programs warmed
    for program in warmed:
        assert program._cache_size() == 1  # the warm-up's trace, not a second one
    for k, want in chain["feats"].items():
        np.testing.assert_array_equal(got[k], np.asarray(want), err_msg=k)
