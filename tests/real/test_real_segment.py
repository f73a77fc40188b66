"""Real scenes: RANSAC table plane and k-means against Open3D and scikit-learn, the table frame
and camera pose on hand-worked planes, normals against Open3D, the voxel grid against numpy,
IoU against the hand segmentation, errors, and the figure."""

import jax
import numpy as np
import pytest

from relaff_jax.errors import UserError
from relaff_jax.config.real import RealConfig
from relaff_jax.real.frame import camera_pose, camera_pose_stats, sim_camera, table_frame, to_table, vectors_to_table
from relaff_jax.real.cloud_features import cloud_normals, pair_features
from relaff_jax.real.segment import fit_table_plane, hand_segmentation, segment_scene
from relaff_jax.real.cloud import make_cloud
from relaff_jax.real.score import object_ious, score_scene
from relaff_jax.real.readers import read_cloud
from relaff_jax.real.show import render_real_scene_png
from relaff_jax.real.ransac import kmeans_from, kmeans_pp_init

from helpers import OSD

DATA = OSD


def _plane_for(height, tilt_deg):
    """Camera-frame plane of a table ``height`` m below a camera tilted ``tilt_deg`` from
    straight down (the camera's x axis parallel to the table)."""
    t = np.radians(tilt_deg)
    n = np.array([0.0, -np.sin(t), -np.cos(t)])  # up, seen from the camera (y down, z forward)
    return np.concatenate([n, [height]])


def test_table_frame_and_camera_pose_hand_worked():
    plane = _plane_for(0.8, 40.0)
    pose = camera_pose(plane)
    assert pose["height"] == pytest.approx(0.8)
    assert pose["tilt_deg"] == pytest.approx(40.0)
    # the camera sits height m up and height * tan(tilt) behind the optical axis' hit point
    np.testing.assert_allclose(pose["position"], [-0.8 * np.tan(np.radians(40)), 0, 0.8], atol=1e-12)
    f = table_frame(plane)
    R = f["rotation"]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    # the optical-axis hit is at depth height / cos(tilt); points on the plane get z = 0
    np.testing.assert_allclose(f["origin"], [0, 0, 0.8 / np.cos(np.radians(40))])
    rng = np.random.default_rng(0)
    on = rng.normal(size=(50, 3))
    on -= (on @ plane[:3] + plane[3])[:, None] * plane[:3]
    np.testing.assert_allclose(to_table(on, f)[:, 2], 0, atol=1e-12)
    np.testing.assert_allclose(vectors_to_table(plane[:3], f), [0, 0, 1], atol=1e-12)
    # x is the viewing direction: a point further along the optical axis has larger x
    assert to_table([0, 0, 2.0], f)[0] > to_table([0, 0, 1.0], f)[0]
    flipped = table_frame(plane, flip=True)["rotation"]
    np.testing.assert_allclose(flipped[:2], -R[:2])
    stats = camera_pose_stats([plane, _plane_for(0.6, 50.0)])
    assert stats["height_mean"] == pytest.approx(0.7)
    assert stats["tilt_std_deg"] == pytest.approx(5.0)
    cam = sim_camera(0.8, 40.0, target=(0.7, 0.0, 0.0))
    assert cam.position == pytest.approx((0.7 + 0.8 * np.tan(np.radians(40)), 0.0, 0.8))
    with pytest.raises(UserError, match="optical axis"):
        table_frame([0.0, -1.0, 0.0, 0.5])  # a plane parallel to the optical axis


def test_hand_segmentation_and_iou_hand_worked():
    lab = np.array([[0, 1, 9, 20], [25, 31, 30, 12]])
    np.testing.assert_array_equal(hand_segmentation(lab), [[0, 1, 1, 2], [2, 3, 3, 0]])
    truth = np.array([1, 1, 2, 2, 2, 3, 3, 0])
    pred = np.array([1, 0, 5, 5, 4, 4, 4, 4])  # 5 matches 2 (IoU 2/3), 4 matches 3 (IoU 2/4)
    r = object_ious(pred, truth)
    assert r["match"] == {2: 5, 3: 4}
    assert r["ious"][2] == pytest.approx(2 / 3)
    assert r["ious"][3] == pytest.approx(0.5)
    assert r["table"] == pytest.approx(0.5)
    # one-to-one: a single predicted blob over both objects matches only one of them
    r = object_ious(np.array([0, 0, 7, 7, 7, 7, 7, 0]), truth)
    assert sorted(r["ious"].values()) == pytest.approx([0.0, 0.6])


@pytest.mark.slow  # compiles k-means++ and Lloyd (~4 s alone, 11 s on a busy machine)
def test_kmeans_matches_scikit_learn():
    from sklearn.cluster import KMeans

    rng = np.random.default_rng(3)
    pts = np.concatenate([rng.normal(c, 0.05, (n, 3)) for c, n in (((0, 0, 0), 70), ((0.3, 0, 0), 50),
                                                                     ((0, 0.25, 0.1), 30))]).astype(np.float32)
    pad = np.concatenate([pts, np.full((106, 3), 9.0, np.float32)])  # padding far away: must not count
    mask = np.arange(len(pad)) < len(pts)
    init = np.asarray(jax.jit(kmeans_pp_init, static_argnums=3)(pad, mask, jax.random.key(0), 3))
    assert all(any(np.all(row == p) for p in pts) for row in init)  # seeds are valid points
    ours = jax.jit(kmeans_from, static_argnums=3)(pad, mask, init, 100)
    sk = KMeans(3, init=init.astype(np.float64), n_init=1, max_iter=100, tol=0.0, algorithm="lloyd").fit(
        pts.astype(np.float64))
    np.testing.assert_array_equal(np.asarray(ours["labels"])[: len(pts)], sk.labels_)
    assert np.all(np.asarray(ours["labels"])[len(pts):] == -1)
    assert float(ours["inertia"]) == pytest.approx(sk.inertia_, rel=1e-4)
    np.testing.assert_allclose(ours["centroids"], sk.cluster_centers_, atol=1e-5)


def _voxels_numpy(p, n, size):
    """Open3D voxel_down_sample semantics in numpy: origin = min - size / 2, centroid and mean
    normal (renormalised) per voxel, voxels ordered by (iz, iy, ix)."""
    ijk = np.floor((p - (p.min(0) - size / 2)) / size).astype(np.int64)
    key = ijk[:, 2] * 1_000_000 + ijk[:, 1] * 1000 + ijk[:, 0]
    u, inv = np.unique(key, return_inverse=True)
    cnt = np.bincount(inv)
    cent = np.stack([np.bincount(inv, p[:, i]) for i in range(3)], 1) / cnt[:, None]
    nm = np.stack([np.bincount(inv, n[:, i]) for i in range(3)], 1)
    return cent, nm / np.linalg.norm(nm, axis=1, keepdims=True)


@pytest.mark.slow  # compiles the voxel grid, PCA and RHF (~10 s)
def test_pair_features_voxels_match_numpy_and_normals_match_open3d():
    import open3d as o3d

    c = read_cloud(DATA / "learn17.pcd")
    hand = hand_segmentation(c.label)
    p_cam = c.xyz[(hand == 2) & c.valid].astype(np.float64)
    n_cam = cloud_normals(p_cam, 20)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p_cam))
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(20))
    dots = np.abs(np.sum(np.asarray(pc.normals) * n_cam, axis=1))
    assert np.median(dots) > 0.9999
    assert np.mean(dots > 0.99) > 0.99
    assert np.all(np.sum(n_cam * -p_cam, axis=1) >= 0)  # oriented towards the camera
    frame = table_frame(fit_table_plane(c.xyz[c.valid], jax.random.key(0))["plane"])
    pa, na = to_table(p_cam, frame), vectors_to_table(n_cam, frame)
    pb = to_table(c.xyz[(hand == 3) & c.valid], frame)
    nb = vectors_to_table(cloud_normals(c.xyz[(hand == 3) & c.valid].astype(np.float64), 20), frame)
    f = pair_features(pa, na, pb, nb)
    cfg = RealConfig()
    for o, (p, n) in enumerate(((pa, na), (pb, nb))):
        cent, nm = _voxels_numpy(p, n, cfg.perception.voxel.size)
        k = int(f["n_points"][o])
        assert k == len(cent)
        np.testing.assert_allclose(f["voxels"]["points"][o][:k], cent, atol=2e-5)
        np.testing.assert_allclose(f["voxels"]["normals"][o][:k], nm, atol=1e-4)
        np.testing.assert_allclose(f["pca"][9 * o: 9 * o + 3], cent.mean(0), atol=2e-5)
        w = np.linalg.eigvalsh(np.cov(cent.T, bias=True))[::-1]
        np.testing.assert_allclose(f["pca"][9 * o + 6: 9 * o + 9], w, rtol=1e-3, atol=1e-7)
    assert f["pca"].shape == (18,)
    assert f["rhf"].shape == (300,)
    assert not f["overflow"]
    np.testing.assert_allclose(f["rhf"].reshape(6, 50).sum(1), 1.0, rtol=1e-5)
    # the upper box (object 3) sits above the lower one: dz of b - a mostly positive
    assert f["pca"][9 + 2] > f["pca"][2]


@pytest.mark.slow  # compiles RANSAC and k-means (~10 s) and runs Open3D's RANSAC
@pytest.mark.parametrize("name", ["learn0.pcd", "learn17.pcd", "learn34.pcd"])
def test_real_scene_plane_matches_open3d_and_segmentation_scores(name):
    import open3d as o3d

    c = read_cloud(DATA / name)
    pts = c.xyz[c.valid].astype(np.float64)
    ours = fit_table_plane(pts, jax.random.key(1))
    o3d.utility.random.seed(0)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    model, idx = pc.segment_plane(distance_threshold=0.01, ransac_n=3, num_iterations=1000)
    model = np.asarray(model) * (1 if model[3] > 0 else -1)
    angle = np.degrees(np.arccos(np.clip(ours["plane"][:3] @ model[:3] / np.linalg.norm(model[:3]), -1, 1)))
    assert angle < 1.0
    assert abs(ours["plane"][3] - model[3] / np.linalg.norm(model[:3])) < 0.005
    theirs = np.zeros(len(pts), bool)
    theirs[np.asarray(idx)] = True
    assert np.count_nonzero(ours["inliers"] & theirs) / np.count_nonzero(ours["inliers"] | theirs) > 0.95
    pose = camera_pose(ours["plane"])
    assert 0.3 < pose["height"] < 1.5
    assert 20 < pose["tilt_deg"] < 80
    r = score_scene(c, jax.random.key(2), known_count=True)
    assert r["table"] > 0.95  # RANSAC finds the hand-labelled table
    assert r["n_true"] == {"learn0.pcd": 2, "learn17.pcd": 2, "learn34.pcd": 3}[name]
    assert 0.0 <= r["mean"] <= 1.0
    assert len(r["ious"]) == r["n_true"]


def test_errors_no_points_no_table_one_object():
    empty = make_cloud(np.full((4, 5, 3), np.nan))
    with pytest.raises(UserError, match="no valid points"):
        segment_scene(empty, jax.random.key(0))
    few = make_cloud(np.random.default_rng(0).normal(size=(100, 3)))
    with pytest.raises(UserError, match="table plane needs"):
        segment_scene(few, jax.random.key(0))
    with pytest.raises(UserError, match="n_objects"):
        segment_scene(few, jax.random.key(0), n_objects=0)
    with pytest.raises(UserError, match="both objects need points"):
        pair_features(np.zeros((0, 3)), np.zeros((0, 3)), np.ones((3, 3)), np.ones((3, 3)))


@pytest.mark.slow  # RANSAC on a random cloud (~5 s of compile)
def test_no_table_is_an_error():
    pts = np.random.default_rng(0).uniform(-1, 1, (20000, 3)) + [0, 0, 2]  # a cube of noise, no plane
    with pytest.raises(UserError, match="no table plane"):
        segment_scene(make_cloud(pts), jax.random.key(0))


@pytest.mark.slow  # segments a scene and compiles the features (~15 s)
def test_figure_of_a_real_scene(tmp_path):
    c = read_cloud(DATA / "learn17.pcd")
    v = render_real_scene_png(c, jax.random.key(0), tmp_path / "s.png")
    png = (tmp_path / "s.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(png) > 50_000
    assert v["pair"] == (2, 3)
    assert v["feats"]["pca"].shape == (18,)
    assert v["pipeline"]["seg"].shape == (480, 640)
