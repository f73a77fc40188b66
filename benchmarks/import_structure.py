"""The package's import structure and the command line's cold start, against a reference tree.

Usage: python benchmarks/import_structure.py [--against SRC] [--repeats 5]

For this checkout and, with ``--against SRC`` (another source tree of the project, e.g. an
exported earlier commit), for that tree too, in the same run (the cold starts of the two trees alternate):

- imports inside function bodies (the ``ast`` of every module): all of them, and those of the
  project's own modules (``relaff_jax...`` or relative);
- lazy package faces: package ``__init__`` modules that define a module-level ``__getattr__``;
- the cold start of ``relaff --help`` and of a ``--set`` refusal (``relaff generate lift
  --samples 10 --out DIR --set foo=1``): a fresh interpreter each (``python -c`` running
  ``cli.main``), best of ``--repeats``, with whether JAX, MuJoCo or scikit-learn got imported.

The other tree is put first on ``PYTHONPATH``, so its ``relaff_jax`` is the one imported.
Prints one table with the ratio (this tree / reference) per row.
"""
from __future__ import annotations

import argparse
import ast
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
PROBE = """
import sys
from relaff_jax import cli
try:
    code = cli.main(sys.argv[1:])
except SystemExit as e:
    code = e.code
print(code, ",".join(sorted(m for m in ("jax", "mujoco", "sklearn") if m in sys.modules)) or "-")
"""


def imports_in_functions(root: Path) -> tuple[int, int]:
    """(all, project's own) import statements nested in a function body, over ``root/relaff_jax``."""
    total = own = 0
    for path in sorted((root / "relaff_jax").rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    total += 1
                    own += any(a.name.split(".")[0] == "relaff_jax" for a in node.names)
                elif isinstance(node, ast.ImportFrom):
                    total += 1
                    own += node.level > 0 or (node.module or "").split(".")[0] == "relaff_jax"
    return total, own  # a function nested in a function is walked twice: none in the package


def lazy_faces(root: Path) -> list[str]:
    """Packages whose ``__init__`` defines a module-level ``__getattr__`` (PEP 562)."""
    out = []
    for init in sorted((root / "relaff_jax").rglob("__init__.py")):
        tree = ast.parse(init.read_text())
        for node in tree.body:
            names = ([node.name] if isinstance(node, ast.FunctionDef) else
                     [t.id for s in ([node] if isinstance(node, ast.Assign) else []) for t in
                      ast.walk(s.targets[0]) if isinstance(t, ast.Name)])
            if "__getattr__" in names:
                out.append(str(init.parent.relative_to(root)).replace("/", "."))
                break
    return out


def cold_start(roots: list[Path], argv: list[str], repeats: int) -> list[tuple[float, str]]:
    """Best wall time of a fresh ``cli.main(argv)`` with each root first on the path, and the heavy
    modules it imported. The roots take turns in every repeat, so that a machine's changing load
    falls on both alike."""
    best, heavy = [float("inf")] * len(roots), [""] * len(roots)
    for _ in range(repeats):
        for i, root in enumerate(roots):
            env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
            t0 = time.perf_counter()
            r = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, env=env,
                               cwd=tempfile.gettempdir())
            best[i] = min(best[i], time.perf_counter() - t0)
            heavy[i] = r.stdout.split()[-1] if r.stdout.split() else f"failed: {r.stderr[-200:]}"
    return list(zip(best, heavy))


def measure(roots: dict[str, Path], repeats: int, tmp: Path) -> dict[str, dict]:
    rows = {}
    for name, root in roots.items():
        total, own = imports_in_functions(root)
        faces = lazy_faces(root)
        rows[name] = {"imports inside functions": total, "  of the project's modules": own,
                      "lazy package faces": len(faces), "_faces": faces}
    paths = list(roots.values())
    helps = cold_start(paths, ["--help"], repeats)
    sets = cold_start(paths, ["generate", "lift", "--samples", "10", "--out", str(tmp / "d"), "--set", "foo=1"], repeats)
    for (name, row), (help_s, help_heavy), (set_s, set_heavy) in zip(rows.items(), helps, sets):
        row.update({"relaff --help (s)": help_s, "--set refusal (s)": set_s,
                    "_heavy": f"--help: {help_heavy}; --set: {set_heavy}"})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", type=Path, help="a reference source tree (holding relaff_jax/)")
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    if a.against is not None and not (a.against / "relaff_jax" / "__init__.py").is_file():
        print(f"benchmarks/import_structure.py: error: {a.against} holds no relaff_jax package", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        roots = {"this tree": HERE} | ({"reference": a.against.resolve()} if a.against is not None else {})
        rows = measure(roots, a.repeats, Path(tmp))
    print(f"python {sys.version.split()[0]}, cold starts best of {a.repeats}")
    cols = list(rows)
    print(f"{'measure':28s}" + "".join(f"{c:>12s}" for c in cols) + ("       ratio" if len(cols) == 2 else ""))
    for key in (k for k in rows["this tree"] if not k.startswith("_")):
        vals = [rows[c][key] for c in cols]
        cells = "".join(f"{v:12.3f}" if isinstance(v, float) else f"{v:12d}" for v in vals)
        ratio = f"{vals[0] / vals[1]:12.2f}" if len(vals) == 2 and vals[1] else ""
        print(f"{key:28s}{cells}{ratio}")
    for c in cols:
        print(f"{c}: lazy faces {', '.join(rows[c]['_faces']) or 'none'}; heavy modules imported: {rows[c]['_heavy']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
