"""The ``relaff real`` stages, one entry point each over the whole ``RunConfig`` tree (its
``real`` node and the ``perception`` it shares with simulation); ``relaff real SUBCOMMAND``
parses its arguments into the tree and calls one of these.

- ``run_segment(tree, scenes, out=None, *, seed, known_count)``: the paper's segmentation scored
  against the hand one (``score.score_scenes``); prints one line per scene and the means,
  writes them to ``out`` (JSON) when given; returns the result dict.
- ``run_show(tree, scene, out, *, seed, pair, source)``: one scene's picture (``show``).
- ``run_propose(tree, scenes, out, *, pictures, corrections)``: the labels file proposed by the
  rule, corrections (a CSV) applied (``labelling.propose_folder``).
- ``run_check(scenes, labels, *, only_present)``: a labels file validated against its scenes
  (no settings).
- ``run_study`` (``study.py``): the sim-to-real study.

``say`` (default ``print``) receives the lines a command shows.
"""
from __future__ import annotations

import csv
from pathlib import Path

from relaff_jax.errors import UserError

from relaff_jax.config.real import pipeline_config
from .study import run_study
from relaff_jax.io import atomic_write_json
from .scene_source import object_ids, scene_files
from .score import score_scenes
from .readers import read_cloud
from .show import render_real_scene_png
from . import labels as lab
from .labelling import propose_folder


def run_segment(tree, scenes: str | Path, out: str | Path | None = None, *, seed: int = 0,
                known_count: bool = False, progress: bool = True, say=print) -> dict:
    """Score the paper's segmentation of every scene of ``scenes`` against the hand one."""
    res = score_scenes(scene_files(scenes), seed=seed, cfg=pipeline_config(tree), known_count=known_count,
                       progress=progress)
    for s in res["scenes"]:
        say(f"{s['scene']}: mean object IoU {s['mean']:.3f}, table {s['table']:.3f}")
    k = tree.real.pipeline.kmeans
    variant = ("k = objects" + (" + 1" if k.background else "") if known_count else f"k = {k.k}") + \
        (", smallest cluster = background" if k.background else ", no background cluster")
    say(f"{variant}: mean IoU over scenes {res['mean_iou']:.3f}, over objects {res['mean_iou_objects']:.3f}, "
        f"table {res['mean_table_iou']:.3f}")
    res = dict(res, variant=variant)
    if out:
        atomic_write_json(out, res)
    return res


def run_show(tree, scene: str | Path, out: str | Path, *, seed: int = 0, pair=None, source: str = "hand",
             say=print) -> Path:
    """Draw one real scene (colour, segmentations, voxel clouds, PCA frames) into ``out``."""
    import jax

    render_real_scene_png(read_cloud(scene), jax.random.PRNGKey(seed), out, pipeline_config(tree), pair=pair,
                          source=source)
    say(str(out))
    return Path(out)


def run_propose(tree, scenes: str | Path, out: str | Path, *, pictures: str | Path | None = None,
                corrections: str | Path | None = None, say=print) -> list:
    """Propose a relation for every pair of ``scenes`` by ``tree.real.rule``, apply the
    ``corrections`` CSV, write the labels file ``out`` (and the pictures); returns the labels."""
    fixes = read_corrections(corrections, scenes)  # every row checked before any proposal
    labels, record = propose_folder(scenes, pictures, fixes, tree.real.rule)
    lab.write_labels(out, labels)
    counts = lab.relation_counts(labels)
    left = sum(r[2] == "none" for r in record)
    say(f"{out}: {counts['beside']} beside, {counts['on_top']} on_top; {left} of {len(record)} pairs left out; "
        f"{len(fixes)} corrections applied")
    return labels


def run_check(scenes: str | Path, labels_path: str | Path, *, only_present: bool = False,
              write_checksums: bool = False, say=print) -> list:
    """Validate a labels file against its scenes and count the pairs (no settings).
    ``write_checksums``: first (re)write its ``sha256`` column from the scene files (the file
    may lack the column), atomically in place."""
    if write_checksums:
        rows = lab.with_checksums(lab.read_labels(labels_path, need_sha256=False), scenes)
        lab.write_labels(labels_path, rows)
        say(f"{labels_path}: sha256 of {len({x.scene for x in rows})} scene files written")
    labels = lab.read_labels(labels_path)
    skipped = []
    if only_present:
        labels, skipped = lab.present(labels, scenes)
    labels = lab.validate(labels, scenes, object_ids)
    counts = lab.relation_counts(labels)
    note = f"; {len(skipped)} labelled scenes not in {scenes} skipped" if only_present else ""
    say(f"{labels_path}: valid; {counts['beside']} beside, {counts['on_top']} on_top in "
        f"{len({x.scene for x in labels})} scenes{note}")
    return labels


def read_corrections(path: str | Path | None, folder: str | Path | None = None) -> dict:
    """The corrections CSV (scene,object_a,object_b,relation) as {(scene, a, b): relation}; {} for None.
    Every row is checked before any proposal is computed: its relation (beside, on_top or
    none), its ids, and with ``folder`` that the scene file is there and holds both objects."""
    if path is None:
        return {}
    if not Path(path).is_file():
        raise UserError(f"corrections file {path} does not exist")
    out = {}
    rows = list(csv.reader(lab.read_text(path, "corrections file").splitlines()))
    if not rows or [c.strip() for c in rows[0]][:4] != ["scene", "object_a", "object_b", "relation"]:
        raise UserError(f"{path}: header must start scene,object_a,object_b,relation")
    ids: dict[str, set] = {}
    for i, r in enumerate(rows[1:], start=2):
        if not r or not any(c.strip() for c in r) or r[0].startswith("#"):
            continue
        where = f"{path} line {i}"
        try:
            scene, a, b, rel = r[0].strip(), int(r[1]), int(r[2]), r[3].strip()
        except (IndexError, ValueError):
            raise UserError(f"{where}: expected scene,object_a,object_b,relation") from None
        if lab.scene_name_problem(scene):
            raise UserError(f"{where}: {lab.scene_name_problem(scene)}")
        if rel not in lab.REAL_RELATIONS + ("none",):
            raise UserError(f"{where}: relation {rel!r} is not beside, on_top or none")
        if a == b or min(a, b) < 2:
            raise UserError(f"{where}: object ids {a},{b} are not two different ids >= 2")
        if (scene, a, b) in out or (scene, b, a) in out:
            raise UserError(f"{where}: pair {a},{b} of {scene} corrected twice")
        if folder is not None:
            if scene not in ids:
                if not (Path(folder) / scene).is_file():
                    raise UserError(f"{where}: no scene {scene!r} in {folder}")
                ids[scene] = {int(x) for x in object_ids(Path(folder) / scene)}
            for oid in (a, b):
                if oid not in ids[scene]:
                    raise UserError(f"{where}: {scene} has no object id {oid} (its objects: {sorted(ids[scene])})")
        out[(scene, a, b)] = rel
    return out


__all__ = ["run_segment", "run_show", "run_propose", "run_check", "run_study", "read_corrections"]
