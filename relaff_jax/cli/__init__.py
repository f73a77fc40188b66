"""The ``relaff`` command line: one subcommand per pipeline stage.

Each module of this package registers the commands of one stage (``register(subparsers)``,
``set_defaults(func=...)``; ``func(args) -> int`` is the exit code) and calls the stage's
library functions; the stages themselves know nothing of argparse.

Errors: a ``relaff_jax.errors.UserError`` (bad option, unusable folder, corrupt data) is
printed as one line, ``relaff COMMAND: error: MESSAGE`` (``relaff real SUBCOMMAND: ...``
for the ``real`` commands), exit code 2, the prefix argparse uses
for its own errors; a full disk (ENOSPC, wherever it surfaces) is one line naming the folder and
the space left, exit code 2. Any other exception is a bug and keeps its full traceback (exit 1).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from relaff_jax import quiet
from relaff_jax.errors import UserError
from relaff_jax.io import disk_full, is_no_space

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


def version() -> str:
    """The installed package's version (and where it runs from)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as v

    try:
        return v("relaff_jax")
    except PackageNotFoundError:  # run from a source tree that was not installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="relaff",
        description="Relational affordances of object pairs: simulate, perceive, learn, bootstrap.",
    )
    parser.add_argument("--version", action="version", version=f"relaff {version()}")
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


def _where(e: BaseException):
    """The folder a failed write named (``OSError.filename``, or a quoted path in the text of
    a wrapped error), else the working folder."""
    import re
    from pathlib import Path

    name = getattr(e, "filename", None)
    if not name:
        m = re.search(r'"(/[^"]+)"', str(e))
        name = m.group(1) if m else None
    return Path(name).parent if name else Path.cwd()


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C: the stages' cleanup and the run log's
    "interrupted" entry run as for an interrupt, and the command ends with one line."""


def _on_sigterm(signum, frame):  # pragma: no cover - exercised through a subprocess
    # An exception raised while a module is being imported can cross a C extension's module
    # init (jaxlib's nanobind), which then aborts the process: during an import, ask again in
    # 0.2 s instead of raising.
    f = frame
    while f is not None:
        if f.f_code.co_filename.startswith("<frozen importlib"):
            import os
            import threading

            threading.Timer(0.2, os.kill, (os.getpid(), signum)).start()
            return
        f = f.f_back
    raise Terminated()


def main(argv: list[str] | None = None) -> int:
    quiet.install()
    import signal
    import threading

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if main_thread else None
    try:
        return _run(argv)
    finally:
        if main_thread:  # a caller (a test, a notebook) keeps its own handler
            signal.signal(signal.SIGTERM, previous)


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    name = command_name(args)
    # loaded when the command runs: every command's parser (--help) imports this module
    from relaff_jax import compile_cache

    # before any JAX work (docs/reproduce.md); traced programs kept with the compiled ones
    compile_cache.enable_traces(compile_cache.configure(disable=args.no_compile_cache))
    try:
        return int(args.func(args) or 0)
    except UserError as e:
        print(f"relaff {name}: error: {e}", file=sys.stderr)
        return 2
    except Exception as e:  # a full disk, wherever it surfaces and whatever wraps it; else a bug
        if not is_no_space(e):
            raise
        print(f"relaff {name}: error: {disk_full(e, _where(e))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        how, code = ("terminated (SIGTERM)", 143) if isinstance(e, Terminated) else ("interrupted", 130)
        print(f"relaff {name}: {how}; what was finished is kept, rerun the same command "
              "to continue", file=sys.stderr)
        return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
