"""From a scenes folder to a labels file: the rule's proposals, pictures, corrections by eye.

Takes a scenes folder (hand-segmented real scenes), optionally a pictures folder and
corrections ``{(scene, a, b): relation or "none"}`` (ids as the rule gives them, i.e. upper
first for on_top; a correction may swap the ids by naming the pair the other way round);
gives ``propose_folder(...) -> (labels, proposals)``: ``labels`` the pairs whose (corrected)
relation is beside or on_top, with each scene file's sha256 (``labels.Label``), and
``proposals`` every pair as ``(scene, Proposal, final relation)`` for the record.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from relaff_jax.errors import UserError

from .labels import REAL_RELATIONS, Label, file_sha256
from relaff_jax.config.real import RuleConfig
from .propose import propose_scene
from .scene_source import load, scene_files
from .pictures import scene_pictures


def propose_folder(folder: str | Path, pictures: str | Path | None = None,
                   corrections: Mapping[tuple[str, int, int], str] | None = None,
                   cfg: RuleConfig = RuleConfig(), progress: bool = True):
    """Proposals for every pair of every scene of ``folder`` (see the module docstring)."""
    corrections = dict(corrections or {})
    used = set()
    labels, record = [], []
    files = scene_files(folder)
    for k, path in enumerate(files):
        scene = load(path)
        props = propose_scene(scene.objects, cfg)
        if pictures is not None:
            scene_pictures(scene, props, pictures)
        digest = file_sha256(path)
        for p in props:
            rel, a, b = p.relation, p.object_a, p.object_b
            for key, swap in (((path.name, a, b), False), ((path.name, b, a), True)):
                if key in corrections:
                    rel = corrections[key]
                    a, b = (b, a) if swap else (a, b)
                    used.add(key)
            if rel not in REAL_RELATIONS + ("none",):
                raise UserError(f"correction for {path.name} {a},{b}: relation {rel!r} is not beside, on_top or none")
            record.append((path.name, p, rel))
            if rel != "none":
                labels.append(Label(path.name, a, b, rel, digest))
        if progress:
            print(f"proposals: {k + 1}/{len(files)} scenes", end="\r", flush=True)
    if progress:
        print()
    unused = set(corrections) - used
    if unused:
        raise UserError(f"corrections name pairs that are not in {folder}: {sorted(unused)}")
    return labels, record
