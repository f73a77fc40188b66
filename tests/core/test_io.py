"""Atomic writes: files and folders get the mode the umask gives (not tempfile's 0600/0700),
the writable-folder check, remove_tree."""
import os
import stat

import pytest

from relaff_jax import io as rio
from relaff_jax.errors import UserError


@pytest.fixture
def umask022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def mode(p):
    return stat.S_IMODE(os.stat(p).st_mode)


def test_files_and_folders_follow_the_umask(tmp_path, umask022):
    rio.atomic_write_json(tmp_path / "a.json", {"x": 1})
    rio.atomic_write_bytes(tmp_path / "b.bin", b"x")
    with rio.atomic_directory(tmp_path / "d") as d:
        rio.atomic_write_text(d / "c.txt", "x")
    assert mode(tmp_path / "a.json") == 0o644
    assert mode(tmp_path / "b.bin") == 0o644
    assert mode(tmp_path / "d") == 0o755
    assert mode(tmp_path / "d" / "c.txt") == 0o644
    os.umask(0o077)
    rio.atomic_write_json(tmp_path / "private.json", {})
    assert mode(tmp_path / "private.json") == 0o600


def test_check_writable_dir(tmp_path):
    f = tmp_path / "f"
    f.write_text("x")
    rio.check_writable_dir(tmp_path / "new" / "deeper")  # creatable: fine, creates nothing
    assert not (tmp_path / "new").exists()
    with pytest.raises(UserError, match="is a file, not a folder"):
        rio.check_writable_dir(f)
    with pytest.raises(UserError, match="is a file, so no folder"):
        rio.check_writable_dir(f / "sub")
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        with pytest.raises(UserError, match="cannot write"):
            rio.check_writable_dir(ro / "x")


def test_check_writable_file(tmp_path):
    f = tmp_path / "f"
    f.write_text("x")
    rio.check_writable_file(tmp_path / "new" / "page.md")  # its folder is creatable: fine, creates nothing
    assert not (tmp_path / "new").exists()
    with pytest.raises(UserError, match="is a folder; give a file name"):
        rio.check_writable_file(tmp_path)
    with pytest.raises(UserError, match="page.md: folder .* is a file"):
        rio.check_writable_file(f / "page.md")


def test_remove_tree_and_leftovers(tmp_path):
    d = tmp_path / "out"
    (d / "sub").mkdir(parents=True)
    (d / "sub" / "f").write_text("x")
    rio.remove_tree(d)
    assert not d.exists()
    assert not list(tmp_path.iterdir())
    (tmp_path / ".out.old.tmp").mkdir()  # what a killed remove_tree leaves
    rio.clean_leftovers(tmp_path)
    assert not list(tmp_path.iterdir())
