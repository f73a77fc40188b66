"""No unused import, undefined name or redefinition in the package, tests, benchmarks and
examples (pyflakes); an import kept on purpose (a re-export, an import for its side effect such
as ``import relaff_jax`` setting XLA's flags) says so with ``# noqa: F401`` on its line."""
import re
from pathlib import Path

import pytest

pyflakes_api = pytest.importorskip("pyflakes.api")
from pyflakes import messages  # noqa: E402
from pyflakes.reporter import Reporter  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


class _Collect(Reporter):
    def __init__(self):
        self.found = []

    def flake(self, message):
        self.found.append(message)

    def syntaxError(self, filename, msg, lineno, offset, text):
        self.found.append(f"{filename}:{lineno}: syntax error {msg}")

    def unexpectedError(self, filename, msg):
        self.found.append(f"{filename}: {msg}")


def _marked(m) -> bool:
    """An unused import whose line carries ``noqa: F401`` (kept on purpose)."""
    if not isinstance(m, messages.UnusedImport):
        return False
    return re.search(r"noqa: ?[A-Z0-9,]*F401", Path(m.filename).read_text().splitlines()[m.lineno - 1]) is not None


def test_pyflakes_finds_nothing_unmarked():
    rep = _Collect()
    paths = [str(ROOT / d) for d in ("relaff_jax", "tests", "benchmarks", "examples")]
    pyflakes_api.checkRecursive(paths, rep)
    bad = [str(m) for m in rep.found if isinstance(m, str) or not _marked(m)]
    assert not bad, "\n".join(bad)


def test_an_unmarked_unused_import_is_found(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("import os\nimport sys  # noqa: F401  (kept)\nprint(undefined_name)\n")
    rep = _Collect()
    pyflakes_api.checkPath(str(src), rep)
    assert sorted((type(m).__name__, m.lineno, _marked(m)) for m in rep.found) == [
        ("UndefinedName", 3, False), ("UnusedImport", 1, False), ("UnusedImport", 2, True)]
