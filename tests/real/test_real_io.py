"""Real point clouds in: PCD (ascii, binary, binary_compressed), PLY, npz readers and writers,
LZF, intrinsics, checked against files the tests write and against Open3D on real scenes."""

import numpy as np
import pytest

from relaff_jax.errors import UserError
from relaff_jax.real.cloud import estimate_intrinsics, make_cloud
from relaff_jax.real.readers import read_cloud, write_npz
from relaff_jax.real.pcd import read_pcd, write_pcd
from relaff_jax.real.ply import write_ply
from relaff_jax.real import lzf
from relaff_jax.real.cloud import pack_rgb, unpack_rgb

from helpers import OSD

DATA = OSD
REAL = sorted(DATA.glob("*.pcd"))
K = (525.0, 520.0, 319.5, 239.5)


def _organized(h=6, w=8, seed=0, rgb=True, label=True):
    """A small organized cloud seen through intrinsics K, with NaN pixels."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:h, 0:w]
    z = rng.uniform(0.5, 1.5, (h, w))
    xyz = np.stack([(u - K[2]) / K[0] * z, (v - K[3]) / K[1] * z, z], -1).astype(np.float32)
    xyz[rng.random((h, w)) < 0.2] = np.nan
    return make_cloud(xyz, rgb=rng.integers(0, 256, (h, w, 3), dtype=np.uint8) if rgb else None,
                      label=rng.integers(0, 60, (h, w)).astype(np.uint32) if label else None,
                      fields={"intensity": rng.random((h, w)).astype(np.float32)}, estimate=False)


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("with_rgb", [True, False])
def test_pcd_round_trip(tmp_path, data, with_rgb):
    c = _organized(rgb=with_rgb)
    write_pcd(tmp_path / "s.pcd", c, data=data)
    r = read_pcd(tmp_path / "s.pcd")
    assert r.xyz.shape == (6, 8, 3)
    assert r.organized
    np.testing.assert_array_equal(r.xyz, c.xyz)  # NaN == NaN here
    assert (r.rgb is None) == (not with_rgb)
    if with_rgb:
        np.testing.assert_array_equal(r.rgb, c.rgb)
    np.testing.assert_array_equal(r.label, c.label)
    np.testing.assert_array_equal(r.fields["intensity"], c.fields["intensity"])
    assert r.intrinsics is None  # 48 pixels: too few (< 100) to estimate intrinsics


def test_pcd_unorganized_any_types_and_counts(tmp_path):
    """A binary PCD written by hand: HEIGHT 1, float64 xyz, int16 field, a COUNT 3 field,
    a float-packed ``rgb`` (as PCL writes it)."""
    n = 5
    rng = np.random.default_rng(1)
    xyz = rng.normal(size=(n, 3))
    xyz[2] = np.nan
    col = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    st = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("rgb", "<f4"), ("ring", "<i2"), ("h", "<f4", (3,))])
    rec = np.zeros(n, st)
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["rgb"] = pack_rgb(col).view(np.float32)
    rec["ring"] = np.arange(n) - 2
    rec["h"] = rng.random((n, 3))
    head = (f"VERSION 0.7\nFIELDS x y z rgb ring h\nSIZE 8 8 8 4 2 4\nTYPE F F F F I F\nCOUNT 1 1 1 1 1 3\n"
            f"WIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary\n")
    (tmp_path / "u.pcd").write_bytes(head.encode() + rec.tobytes())
    r = read_pcd(tmp_path / "u.pcd")
    assert r.xyz.shape == (n, 3)
    assert not r.organized
    assert r.intrinsics is None
    np.testing.assert_array_equal(r.xyz, xyz.astype(np.float32))
    np.testing.assert_array_equal(r.rgb, col)
    np.testing.assert_array_equal(r.fields["ring"], np.arange(n) - 2)
    assert r.fields["h"].shape == (n, 3)


def test_pcd_ascii_by_hand(tmp_path):
    txt = ("# comment\nVERSION .7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F U\nWIDTH 3\nHEIGHT 1\n"
           "POINTS 3\nDATA ascii\n0.1 0.2 1.5 1\nnan nan nan 0\n-1e-1 2 3 25\n")
    (tmp_path / "a.pcd").write_text(txt)
    r = read_cloud(tmp_path / "a.pcd")
    np.testing.assert_array_equal(r.valid, [True, False, True])
    np.testing.assert_allclose(r.xyz[2], [-0.1, 2, 3])
    np.testing.assert_array_equal(r.label, [1, 0, 25])
    assert r.rgb is None


def _bad(tmp_path, text: bytes, match):
    p = tmp_path / "bad.pcd"
    p.write_bytes(text)
    with pytest.raises(UserError, match=match):
        read_pcd(p)


def test_pcd_errors(tmp_path):
    c = _organized()
    for data in ("binary", "binary_compressed"):
        write_pcd(tmp_path / "ok.pcd", c, data=data)
        raw = (tmp_path / "ok.pcd").read_bytes()
        _bad(tmp_path, raw[:-10], "truncated")
    head = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\n"
    _bad(tmp_path, (head + "DATA zip\n").encode(), "unknown DATA")
    _bad(tmp_path, head.replace("POINTS 2", "POINTS 3").encode() + b"DATA ascii\n1 2 3\n4 5 6\n", "POINTS")
    _bad(tmp_path, head.replace("SIZE 4 4 4", "SIZE 4 4").encode() + b"DATA ascii\n", "one entry per field")
    _bad(tmp_path, head.replace("FIELDS x y z", "FIELDS x y w").encode() + b"DATA ascii\n1 2 3\n4 5 6\n", "'z'")
    _bad(tmp_path, head.encode() + b"DATA ascii\n1 2 3\n4 5\n", "truncated ascii")
    _bad(tmp_path, head.encode(), "no DATA")
    # a corrupt LZF stream: sizes in the header are right, the payload is garbage
    raw = (tmp_path / "ok.pcd").read_bytes()
    off = raw.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    _bad(tmp_path, raw[: off + 8] + b"\xff" * (len(raw) - off - 8), "corrupt LZF")
    with pytest.raises(UserError, match="unknown point-cloud format"):
        (tmp_path / "x.xyz").write_text("1 2 3\n")
        read_cloud(tmp_path / "x.xyz")
    with pytest.raises(UserError, match="no such"):
        read_cloud(tmp_path / "missing.pcd")


@pytest.mark.parametrize("binary", [True, False])
def test_ply_round_trip(tmp_path, binary):
    c = _organized()
    write_ply(tmp_path / "s.ply", c, binary=binary)
    r = read_cloud(tmp_path / "s.ply")
    np.testing.assert_array_equal(r.xyz, c.xyz.reshape(-1, 3))
    np.testing.assert_array_equal(r.rgb, c.rgb.reshape(-1, 3))


def test_ply_by_hand_and_errors(tmp_path):
    txt = ("ply\nformat ascii 1.0\ncomment hi\nelement vertex 2\nproperty double x\nproperty double y\n"
           "property double z\nproperty float nx\nelement face 1\nproperty list uchar int vertex_indices\n"
           "end_header\n1 2 3 0.5\n4 5 6 -0.5\n3 0 1 1\n")
    (tmp_path / "h.ply").write_text(txt)
    r = read_cloud(tmp_path / "h.ply")
    np.testing.assert_array_equal(r.xyz, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(r.fields["nx"], [0.5, -0.5])
    assert r.rgb is None
    (tmp_path / "b.ply").write_text(txt.replace("ascii", "binary_big_endian"))
    with pytest.raises(UserError, match="unsupported PLY format"):
        read_cloud(tmp_path / "b.ply")
    (tmp_path / "n.ply").write_text(txt.replace("property double z\n", ""))
    with pytest.raises(UserError, match="x, y and z"):
        read_cloud(tmp_path / "n.ply")
    c = _organized()
    write_ply(tmp_path / "t.ply", c)
    (tmp_path / "t.ply").write_bytes((tmp_path / "t.ply").read_bytes()[:-7])
    with pytest.raises(UserError, match="truncated"):
        read_cloud(tmp_path / "t.ply")


def test_npz_round_trip_and_errors(tmp_path):
    c = _organized()
    c = make_cloud(c.xyz, rgb=c.rgb, label=c.label, intrinsics=K)
    write_npz(tmp_path / "s.npz", c)
    r = read_cloud(tmp_path / "s.npz")
    np.testing.assert_array_equal(r.xyz, c.xyz)
    np.testing.assert_array_equal(r.rgb, c.rgb)
    np.testing.assert_array_equal(r.label, c.label)
    assert r.intrinsics == K
    assert r.intrinsics_source == "file"
    np.savez(tmp_path / "only.npz", xyz=c.xyz.reshape(-1, 3))
    r = read_cloud(tmp_path / "only.npz")
    assert r.rgb is None
    assert r.label is None
    assert r.xyz.shape == (48, 3)
    np.savez(tmp_path / "bad.npz", points=c.xyz)
    with pytest.raises(UserError, match="no 'xyz'"):
        read_cloud(tmp_path / "bad.npz")
    np.savez(tmp_path / "bad2.npz", xyz=c.xyz, rgb=np.zeros((2, 3), np.uint8))
    with pytest.raises(UserError, match="rgb shape"):
        read_cloud(tmp_path / "bad2.npz")


def test_lzf_c_path_matches_pure_python():
    rng = np.random.default_rng(2)
    data = (np.repeat(rng.integers(0, 7, 3000), rng.integers(1, 40, 3000)).astype(np.uint8).tobytes()
            + rng.bytes(500) + b"abc" * 300)
    comp = lzf.compress(data)
    assert len(comp) < len(data)
    assert lzf.decompress(comp, len(data)) == data == lzf.decompress_py(comp, len(data))
    with pytest.raises(UserError, match="corrupt LZF"):
        lzf.decompress_py(comp, len(data) + 1)


def test_colour_packing():
    rgb = np.array([[255, 0, 16], [1, 2, 3]], np.uint8)
    packed = pack_rgb(rgb)
    assert packed[0] == 0xFFFF0010
    np.testing.assert_array_equal(unpack_rgb(packed), rgb)
    np.testing.assert_array_equal(unpack_rgb(packed.view(np.float32)), rgb)


def test_intrinsics_fit_recovers_a_known_camera():
    c = _organized(h=20, w=30)
    fit = estimate_intrinsics(c.xyz)
    np.testing.assert_allclose(fit["intrinsics"], K, rtol=1e-4)
    assert max(fit["rms_px"]) < 1e-3
    assert estimate_intrinsics(np.full((4, 4, 3), np.nan)) is None


@pytest.mark.slow  # Open3D import + a 1 s pure-Python LZF decode: ~5 s
@pytest.mark.parametrize("path", REAL, ids=lambda p: p.name)
def test_real_scene_matches_open3d(path):
    import open3d as o3d

    c = read_cloud(path)
    pc = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
    np.testing.assert_array_equal(np.asarray(pc.points), c.xyz.reshape(-1, 3).astype(np.float64))
    np.testing.assert_array_equal(np.round(np.asarray(pc.colors) * 255), c.rgb.reshape(-1, 3))
    assert c.xyz.shape == (480, 640, 3)
    assert c.label.shape == (480, 640)
    np.testing.assert_array_equal(c.valid, c.label > 0)  # label 0 marks exactly the NaN pixels
    np.testing.assert_allclose(c.intrinsics, (525.0, 525.0, 319.5, 239.5), atol=1e-3)
    assert c.intrinsics_source == "estimated"
    # the pure-Python LZF path decodes the real payload identically
    raw = path.read_bytes()
    off = raw.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    cs, us = (int(v) for v in np.frombuffer(raw, "<u4", 2, off))
    if path == REAL[0]:
        assert lzf.decompress_py(raw[off + 8: off + 8 + cs], us) == lzf.decompress(raw[off + 8: off + 8 + cs], us)
