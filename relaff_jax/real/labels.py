"""Relation labels of real object pairs: the labels CSV the project ships with its scenes.

Takes and gives a CSV file with the header ``scene,object_a,object_b,relation,sha256``, one row
per labelled pair: ``scene`` a file name in the scenes folder (e.g. ``learn17.pcd``),
``object_a`` / ``object_b`` object ids (the scene's per-point ``label // 10``, >= 2, as the
Object Segmentation Database defines them), ``relation`` ``beside`` or ``on_top`` (for
``on_top`` the upper object is ``object_a``), ``sha256`` the hex digest of the scene file
(the same on every row of a scene). Pairs that are neither are left out of the file.

``read_labels(path) -> list[Label]`` checks the format; ``validate(labels, folder,
object_ids)`` checks the rows against a scenes folder (unknown scene, object id missing from
the scene, checksum mismatch); ``write_labels(path, labels)`` writes atomically;
``present(labels, folder)`` keeps the rows of the scenes a folder holds. Every
problem is a ``UserError`` naming the file, the row and what is wrong.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from relaff_jax.errors import UserError
from relaff_jax.io import atomic_write_text

HEADER = ("scene", "object_a", "object_b", "relation", "sha256")
# The relations a real pair can carry (``inside`` exists in simulation only).
REAL_RELATIONS = ("beside", "on_top")


@dataclasses.dataclass(frozen=True)
class Label:
    """One labelled pair: scene file name, object ids a and b, relation, scene sha256."""

    scene: str
    object_a: int
    object_b: int
    relation: str
    sha256: str


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _parse_id(text: str, where: str, column: str) -> int:
    try:
        value = int(text)
    except (TypeError, ValueError):
        raise UserError(f"{where}: {column} {text!r} is not an integer object id") from None
    if value < 2:
        raise UserError(f"{where}: {column} {value} is not an object id (object ids are label // 10 >= 2)")
    return value


def read_text(path: str | Path, what: str = "labels file") -> str:
    """A CSV file's text: UTF-8, with or without the byte-order mark a spreadsheet writes;
    another encoding is a ``UserError`` naming the file, the line and the byte."""
    path = Path(path)
    data = path.read_bytes()
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        guess = " (it looks like Latin-1 or Windows-1252)" if all(b < 0x80 or b >= 0xa0 for b in data) else ""
        raise UserError(f"{what} {path}: not UTF-8{guess}: byte 0x{data[e.start]:02x} on line {line}; save it as "
                        "UTF-8 (in a spreadsheet: 'CSV UTF-8')") from None


def scene_name_problem(scene: str) -> str | None:
    """Why ``scene`` cannot name a file of the scenes folder (a path leaving it, an absolute
    path, a sub-folder), or None: a labels file names files in its folder only, so that it
    can neither open nor hash files elsewhere."""
    if scene in (".", "..") or "/" in scene or "\\" in scene or "\0" in scene or Path(scene).is_absolute():
        return (f"scene {scene!r} is not a file name in the scenes folder (no folders, '..' or absolute paths; "
                "e.g. learn17.pcd)")
    return None


NO_SHA_HINT = ("make it with `relaff real check SCENES --labels L --write-checksums`, which adds the column "
               "from the scene files")


def parse_labels(text: str, name: str = "labels", *, need_sha256: bool = True) -> list[Label]:
    """Rows of a labels CSV given as text; raises ``UserError`` on a bad header or row.
    ``need_sha256=False``: the ``sha256`` column may be absent (rows get ``sha256=""``), as
    ``--write-checksums`` reads a file before it adds the column."""
    reader = csv.reader(io.StringIO(text.removeprefix("\ufeff")))
    rows = [r for r in reader if r and any(c.strip() for c in r)]
    if not rows:
        raise UserError(f"{name}: empty labels file (expected the header {','.join(HEADER)})")
    header = tuple(c.strip() for c in rows[0])
    no_sha = header == HEADER[:-1]
    if no_sha:
        if need_sha256:
            raise UserError(f"{name}: no sha256 column (the scene files' checksums); {NO_SHA_HINT}")
        rows = [r + ["0" * 64] for r in rows]
        header = HEADER
    if header != HEADER:
        raise UserError(f"{name}: header is {','.join(header)!r}, expected {','.join(HEADER)!r}")
    out, seen, digests = [], set(), {}
    for i, row in enumerate(rows[1:], start=2):
        where = f"{name} line {i}"
        if len(row) != len(HEADER):
            raise UserError(f"{where}: {len(row)} columns, expected {len(HEADER)} ({','.join(HEADER)})")
        scene, a, b, rel, digest = (c.strip() for c in row)
        if not scene:
            raise UserError(f"{where}: empty scene name")
        if scene_name_problem(scene):
            raise UserError(f"{where}: {scene_name_problem(scene)}")
        ia, ib = _parse_id(a, where, "object_a"), _parse_id(b, where, "object_b")
        if ia == ib:
            raise UserError(f"{where}: object_a and object_b are both {ia}")
        if rel not in REAL_RELATIONS:
            raise UserError(f"{where}: relation {rel!r} is not one of {', '.join(REAL_RELATIONS)}")
        if len(digest) != 64 or any(c not in "0123456789abcdef" for c in digest.lower()):
            raise UserError(f"{where}: sha256 {digest!r} is not 64 hex digits")
        key = (scene, min(ia, ib), max(ia, ib))
        if key in seen:
            raise UserError(f"{where}: pair {ia},{ib} of {scene} is labelled twice")
        seen.add(key)
        if digests.setdefault(scene, digest.lower()) != digest.lower():
            raise UserError(f"{where}: {scene} has two different sha256 values in the file")
        out.append(Label(scene, ia, ib, rel, "" if no_sha else digest.lower()))
    return out


def read_labels(path: str | Path, *, need_sha256: bool = True) -> list[Label]:
    """The rows of the labels CSV at ``path`` (format checks only; see ``validate``)."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"labels file {path} does not exist")
    return parse_labels(read_text(path), str(path), need_sha256=need_sha256)


def with_checksums(labels: Sequence[Label], folder: str | Path) -> list[Label]:
    """``labels`` with each scene file's sha256 (``--write-checksums``); a scene missing from
    ``folder`` is a ``UserError``."""
    folder, sums, out = Path(folder), {}, []
    for lab in labels:
        if lab.scene not in sums:
            if not (folder / lab.scene).is_file():
                raise UserError(f"labels name an unknown scene {lab.scene!r}: no such file in {folder}")
            sums[lab.scene] = file_sha256(folder / lab.scene)
        out.append(dataclasses.replace(lab, sha256=sums[lab.scene]))
    return out


def format_labels(labels: Iterable[Label]) -> str:
    """CSV text of ``labels`` (header first; rows in the given order)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(HEADER)
    for lab in labels:
        w.writerow([lab.scene, lab.object_a, lab.object_b, lab.relation, lab.sha256])
    return buf.getvalue()


def write_labels(path: str | Path, labels: Sequence[Label]) -> Path:
    """Write ``labels`` atomically after checking they parse back to the same rows."""
    text = format_labels(labels)
    if parse_labels(text, str(path)) != list(labels):
        raise UserError(f"{path}: labels do not survive a round trip (bad ids or relation)")
    atomic_write_text(path, text)
    return Path(path)


def validate(labels: Sequence[Label], folder: str | Path,
             object_ids: Callable[[Path], Iterable[int]]) -> list[Label]:
    """Check ``labels`` against the scenes in ``folder``: each scene file exists, its sha256
    matches, each object id occurs in it (``object_ids(path)`` gives a scene's object ids).
    Returns ``labels`` unchanged; raises ``UserError`` naming the first problem."""
    folder = Path(folder)
    ids_cache: dict[str, set[int]] = {}
    for lab in labels:
        if scene_name_problem(lab.scene):
            raise UserError(scene_name_problem(lab.scene))
        path = folder / lab.scene
        if lab.scene not in ids_cache:
            if not path.is_file():
                raise UserError(f"labels name an unknown scene {lab.scene!r}: no such file in {folder}")
            digest = file_sha256(path)
            if digest != lab.sha256:
                raise UserError(f"checksum mismatch for {lab.scene}: the file's sha256 is {digest}, "
                                f"the labels file has {lab.sha256} (the scene changed since it was labelled)")
            ids_cache[lab.scene] = {int(i) for i in object_ids(path)}
        for oid in (lab.object_a, lab.object_b):
            if oid not in ids_cache[lab.scene]:
                raise UserError(f"{lab.scene} has no object id {oid} (its objects: "
                                f"{sorted(ids_cache[lab.scene])})")
    return list(labels)


def present(labels: Sequence[Label], folder: str | Path) -> tuple[list[Label], list[str]]:
    """The rows whose scene file is in ``folder`` and the names of the labelled scenes it does
    not hold (``--only-present``: work on the scenes a folder holds)."""
    folder = Path(folder)
    names = sorted({lab.scene for lab in labels})
    missing = [n for n in names if not (folder / n).is_file()]
    gone = set(missing)
    return [lab for lab in labels if lab.scene not in gone], missing


def rows_sha256(labels: Sequence[Label]) -> str:
    """Hex sha256 of the rows as a labels file would hold them (a key for caches)."""
    return hashlib.sha256(format_labels(labels).encode()).hexdigest()


def relation_counts(labels: Sequence[Label]) -> dict[str, int]:
    """Pairs per relation, every relation of ``REAL_RELATIONS`` present (0 if none)."""
    return {r: sum(lab.relation == r for lab in labels) for r in REAL_RELATIONS}
