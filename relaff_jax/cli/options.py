"""Options every command shares: ``--set dotted.key=value`` on the one config tree, and
checks of output paths made before any work starts."""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from relaff_jax.config import parse_set
from relaff_jax.errors import UserError


def add_set(p: argparse.ArgumentParser, example: str = "perception.voxel.size=0.02") -> None:
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help=f"override a setting of the config tree (repeatable), e.g. --set {example}; "
                        "an unknown key lists the valid ones")


def config(args: argparse.Namespace, base: Any = None) -> Any:
    """The resolved ``RunConfig``: ``base`` (default: the paper's settings) plus ``--set``."""
    from relaff_jax.runconfig import resolve

    return resolve(base, parse_set(args.set or []))


def check_out_dir(path: Path, what: str = "--out") -> None:
    """An output folder must be a folder (or not exist yet) and its nearest existing ancestor
    writable; checked before any simulation or learning, so a typo costs no minutes."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{what} {path} exists and is a file, not a folder")
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise UserError(f"{what} {path}: {probe} is a file, so no folder can be made under it")
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as e:
        raise UserError(f"{what} {path}: cannot write in {probe} ({e.strerror or e})") from e


def check_out_file(path: Path, what: str = "--out") -> None:
    """An output file must not be a folder, and its folder must be creatable and writable."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{what} {path} is a folder; give a file name")
    check_out_dir(path.parent, what=f"{what} {path}: folder")
