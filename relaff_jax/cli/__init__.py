"""The ``relaff`` command line: one subcommand per pipeline stage.

Each stage module that offers commands has ``register_cli(subparsers)``, which adds
its subcommands with ``set_defaults(func=...)``; ``func(args) -> int`` is the exit code.
Modules are imported lazily by name so that a broken optional stage cannot break the
others, and so that ``relaff --help`` stays fast.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import sys

# Stage modules that contribute subcommands, in pipeline order.
COMMAND_MODULES = (
    "relaff_jax.sim.objects",
    "relaff_jax.sim.scenes",
    "relaff_jax.sim.actions",
    "relaff_jax.data.dataset",
    "relaff_jax.perception.from_sim",
    "relaff_jax.learn.experiment",
    "relaff_jax.reproduce.run",
)


class UserError(Exception):
    """An error caused by the user's input; printed without a traceback."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="relaff",
        description="Relational affordances of object pairs: simulate, perceive, learn, bootstrap.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register_cli(sub)
    return parser


def _quiet_mjx_import() -> None:
    """mujoco.mjx prints "Failed to import warp" to stdout when the optional GPU backend is
    absent (always, on this CPU-only project); send it to stderr so --json output stays JSON."""
    with contextlib.redirect_stdout(sys.stderr):
        importlib.import_module("mujoco.mjx")


def main(argv: list[str] | None = None) -> int:
    _quiet_mjx_import()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (UserError, ValueError, KeyError, FileNotFoundError, FileExistsError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        print(f"relaff {args.command}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
