"""Every subpackage of relaff_jax is listed in pyproject.toml, so a wheel (not only an editable
install, which finds unlisted subpackages through the top-level folder) holds all the code."""
import tomllib

from helpers import ROOT


def test_every_subpackage_is_listed_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "relaff_jax").rglob("__init__.py")}
    assert found, "no package found under relaff_jax/"
    assert found - listed == set(), f"subpackages missing from [tool.setuptools] packages: {sorted(found - listed)}"
