"""The ``relaff`` command line: one subcommand per pipeline stage.

Each module of this package registers the commands of one stage (``register(subparsers)``,
``set_defaults(func=...)``; ``func(args) -> int`` is the exit code) and calls the stage's
library functions; the stages themselves know nothing of argparse.

Errors: a ``relaff_jax.errors.UserError`` (bad option, unusable folder, corrupt data) is
printed as one line, ``relaff COMMAND: error: MESSAGE`` (``relaff real SUBCOMMAND: ...``
for the ``real`` commands), exit code 2, the prefix argparse uses
for its own errors. Any other exception is a bug and keeps its full traceback (exit 1).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from relaff_jax import quiet
from relaff_jax.errors import UserError

# Modules that contribute subcommands, in pipeline order.
COMMAND_MODULES = (
    "relaff_jax.cli.sim",
    "relaff_jax.cli.data",
    "relaff_jax.cli.perception",
    "relaff_jax.cli.learn",
    "relaff_jax.cli.reproduce",
    "relaff_jax.cli.real",
)


class HelpFormatter(argparse.HelpFormatter):
    """Adds ``(default: X)`` to an option's help when it has a default worth naming (not
    None, False or empty, and not already in the text)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        d = action.default
        if (d is None or d is False or d is argparse.SUPPRESS or (isinstance(d, (list, tuple)) and not d)
                or "default" in text or not (action.option_strings or action.nargs in ("?", "*"))):
            return text
        if isinstance(d, (list, tuple)):
            return f"{text} (default: {' '.join(map(str, d))})"
        return f"{text} (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """Every ``relaff`` (sub)command's parser: defaults shown in ``--help``; a subcommand
    without its own description takes its one-line help as the description."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self.register("action", "parsers", _Commands)  # registries are per parser: ``real``'s too


class _Commands(argparse._SubParsersAction):
    def add_parser(self, name, **kwargs):
        if "help" in kwargs and "description" not in kwargs:
            kwargs["description"] = kwargs["help"][:1].upper() + kwargs["help"][1:] + "."
        return super().add_parser(name, **kwargs)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="relaff",
        description="Relational affordances of object pairs: simulate, perceive, learn, bootstrap.",
    )
    parser.add_argument("--no-compile-cache", action="store_true",
                        help="do not use JAX's persistent compilation cache (on by default in "
                             "$XDG_CACHE_HOME/relaff_jax/jax; RELAFF_COMPILE_CACHE=0 does the same, "
                             "RELAFF_COMPILE_CACHE=DIR moves it)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def command_name(args: argparse.Namespace) -> str:
    """The command as typed, subcommand included (``real study``), for error lines."""
    return " ".join(x for x in (args.command, getattr(args, "real_command", None)) if x)


def main(argv: list[str] | None = None) -> int:
    quiet.install()
    parser = build_parser()
    args = parser.parse_args(argv)
    name = command_name(args)
    from relaff_jax import compile_cache

    compile_cache.configure(disable=args.no_compile_cache)  # before any JAX work (docs/reproduce.md)
    try:
        return int(args.func(args) or 0)
    except UserError as e:
        print(f"relaff {name}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"relaff {name}: interrupted; what was finished is kept, rerun the same command "
              "to continue", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
