"""Options every command shares: ``--set dotted.key=value`` on the one config tree, and
checks of output paths made before any work starts."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from relaff_jax.config import parse_set
from relaff_jax.io import check_writable_dir, check_writable_file
from relaff_jax.errors import UserError
from relaff_jax.config import precheck as check
from relaff_jax.plugins import load_file
from relaff_jax.constants import ACTIONS
from relaff_jax.sim.actions.registry import action_id
from relaff_jax.config.action import ActionConfig
from relaff_jax import cluster as C


def add_set(p: argparse.ArgumentParser, example: str = "perception.voxel.size=0.02") -> None:
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help=f"override a setting of the config tree (repeatable), e.g. --set {example}; "
                        "an unknown key lists the valid ones")


def precheck(args: argparse.Namespace, extra: list[str] = ()) -> None:
    """The ``--set`` keys that can be checked without importing JAX (``config.precheck``):
    called first by the commands that import their stage before resolving the config."""
    check({**parse_set(extra), **parse_set(args.set or [])})


def config(args: argparse.Namespace, base: Any = None, extra: list[str] = (),
           flags: dict[str, tuple[str, Any]] | None = None) -> Any:
    """The resolved ``RunConfig``: ``base`` (default: the paper's settings), then the
    command's own options given as ``extra`` ``KEY=VALUE`` items, then ``--set`` (which wins).

    ``flags``: the command's options that are aliases of tree keys, ``{key: (flag, value)}``
    (``{"dataset.n_samples": ("--samples", 100)}``; a value of None: not given). A flag and a
    ``--set`` of its key that disagree are an error, so what runs is what is recorded."""
    # not at the top: this module's own precheck() would shadow config.precheck
    from relaff_jax.config import check_tree, precheck, resolve

    overrides = {**parse_set(extra), **overrides_of(args, flags)}
    try:
        precheck(overrides)  # a mistyped key or a bad value is reported before the preset is built
        return check_tree(resolve(base, overrides))  # the whole tree, before any stage starts
    except UserError as e:  # a value given by a flag: the message names the flag too
        msg = str(e)
        sets = parse_set(args.set or [])
        named = [(k, flag) for k, (flag, v) in (flags or {}).items() if v is not None and k not in sets and k in msg]
        if not named:
            raise
        for key, flag in named:
            msg = msg.replace(key, f"{flag} ({key})", 1)
        raise UserError(msg) from e


def overrides_of(args: argparse.Namespace, flags: dict[str, tuple[str, Any]] | None = None) -> dict[str, Any]:
    """The tree keys the command's flags and ``--set`` give (``--set`` and an aliased flag
    together only if they agree): ``flags`` as ``config`` takes them."""
    sets = parse_set(args.set or [])
    out = {}
    for key, (flag, value) in (flags or {}).items():
        if value is None:
            continue
        if key in sets and sets[key] != value:
            raise UserError(f"{flag} {value} and --set {key}={sets[key]} disagree; give one of them")
        out[key] = value
    return {**out, **sets}


_RANGES = {"seed": (0, 2**32, "a seed"), "jobs": (0, 4096, "a number of worker processes (0: all cores)"),
           "index": (0, None, "a sample index")}


def check_counts(args: argparse.Namespace, **flags: str) -> None:
    """The command's integer options ``{attribute: flag}`` in their ranges (a seed in
    [0, 2**32), jobs >= 0, ...): one line before any work, not a numpy error after it."""
    for attr, flag in flags.items():
        value = getattr(args, attr, None)
        if value is None:
            continue
        lo, hi, what = _RANGES[attr]
        if value < lo or (hi is not None and value >= hi):
            span = f">= {lo}" if hi is None else f"in [{lo}, {hi if hi < 2**20 else '2**32'})"
            raise UserError(f"{flag} is {what} {span}, got {value}")


def check_out_dir(path: Path, what: str = "--out") -> None:
    """An output folder must be a folder (or not exist yet) in a writable place
    (``relaff_jax.io.check_writable_dir``)."""
    check_writable_dir(path, what)


def check_out_file(path: Path, what: str = "--out") -> None:
    """An output file must not be a folder, and its folder must be creatable and writable
    (``relaff_jax.io.check_writable_file``)."""
    check_writable_file(path, what)


def check_in_dir(path: Path, message: str | None = None) -> None:
    """An input folder must exist: checked first, before the command imports its stage (seconds);
    ``message`` defaults to the dataset store's own."""
    if not Path(path).is_dir():
        raise UserError(message or f"{path}: no such dataset directory")


def check_in_file(path: Path, message: str) -> None:
    """An input file must exist: checked first, before the command imports its stage."""
    if not Path(path).is_file():
        raise UserError(message)


def add_plugins(p: argparse.ArgumentParser) -> None:
    """``--plugins FILE.py ...``: Python files registering user actions (or conditions)."""
    p.add_argument("--plugins", nargs="+", metavar="FILE.py", default=None,
                   help="Python files that register user actions (relaff_jax.sim.actions.register_action) "
                        "or conditions, loaded before anything else (docs/extending.md)")


def load_plugins(args: argparse.Namespace) -> None:
    """Execute the ``--plugins`` files (one loader for actions and conditions, ``relaff_jax.plugins``)."""
    for path in getattr(args, "plugins", None) or ():
        load_file(path)


def check_action(args: argparse.Namespace, action: str, cfg: Any = None) -> None:
    """``action`` is built-in or registered (after ``load_plugins``); a user action's rules are
    traced once on a dummy scene (``sim.actions.check.check_actions``): one line before any simulation.
    A user action cannot run on a cluster: the workers would not have its plugin."""
    action_id(action)
    if action in ACTIONS:
        return
    if getattr(args, "cluster", None):
        raise UserError(f"--cluster: the user action {action!r} runs only here (the cluster's workers do not "
                        "load --plugins files)")

    # the trace imports JAX: loaded for a user action only, not by --help or a --set check
    from relaff_jax.sim.actions.check import check_actions

    check_actions([action], cfg if cfg is not None else ActionConfig())


def add_cluster(p: argparse.ArgumentParser) -> None:
    """``--cluster ADDRESS``: run the command's pieces as tasks on a Dask cluster."""
    p.add_argument("--cluster", metavar="ADDRESS", default=None,
                   help="run the pieces as tasks on a Dask cluster: local:N (N worker processes here) or "
                        "tcp://HOST:PORT (a running scheduler); the output folder must be shared with the "
                        "workers (docs/cluster.md). Results are bit-identical to a run without it")


def cluster(args: argparse.Namespace, folder: Path):
    """Context manager: None without ``--cluster``, else a checked ``distributed.Client`` (the
    address parsed and the scheduler reached, versions and ``folder`` checked on every worker,
    before any work); prints the cluster and its dashboard address on stderr."""
    import contextlib
    import sys

    address = getattr(args, "cluster", None)
    if address is None:
        return contextlib.nullcontext(None)

    addr = C.parse_address(address)

    @contextlib.contextmanager
    def run():
        with C.connect(addr, folder=folder) as client:
            print(f"relaff {args.command}: {C.describe(client)}", file=sys.stderr)
            yield client

    return run()


class PhaseBars:
    """``progress(phase, done, total)`` callbacks as one tqdm bar per phase on stderr (a phase
    of one step shows its elapsed time while it runs): what long single-item commands report."""

    def __init__(self, command: str, enabled: bool = True):
        self.command, self.enabled, self.bar, self.phase = command, enabled, None, None

    def __call__(self, phase: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if phase != self.phase:
            self.close()
            from tqdm.auto import tqdm

            self.phase = phase
            self.bar = tqdm(total=total, desc=f"{self.command}: {phase}", dynamic_ncols=True,
                            bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}]")
        self.bar.update(done - self.bar.n)
        if done >= total:
            self.close()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        self.bar, self.phase = None, None
