"""Each node is checked once per node built: the one generic checker, counted while one command's
config is resolved (``--set perception.voxel.size=0.02`` on the tiny preset)."""
from __future__ import annotations

import collections
import dataclasses
import subprocess
import sys

import relaff_jax.config as C
from relaff_jax.config import constraints


def test_each_node_checked_once_per_build(monkeypatch):
    base = C.preset("tiny")
    checked, built = collections.Counter(), collections.Counter()
    real_check = constraints.check_node
    monkeypatch.setattr(constraints, "check_node", lambda node: (checked.update([type(node).__name__]),
                                                                 real_check(node))[1])
    for cls in {type(n) for n in _nodes(base)} | {C.RealConfig, C.RealExperimentConfig}:

        def counted(self, *a, __init=cls.__init__, **k):
            built.update([type(self).__name__])
            __init(self, *a, **k)
        monkeypatch.setattr(cls, "__init__", counted)
    C.precheck({"perception.voxel.size": 0.02})
    tree = C.check_tree(C.resolve(base, {"perception.voxel.size": 0.02}))
    assert tree.perception.voxel.size == 0.02
    assert checked == built  # no node checked twice, none built unchecked
    # precheck builds the default perception node and its copy with the new voxel; resolve the
    # voxel, perception and root nodes; check_tree the real capacity's voxel and perception
    assert checked["VoxelConfig"] == 3 and checked["PerceptionConfig"] == 4 and checked["RunConfig"] == 1
    assert checked["RealConfig"] == 1 and checked["RealExperimentConfig"] == 1 and checked["ExperimentConfig"] == 0 and checked["ActionConfig"] == 0


def _nodes(node):
    yield node
    for f in dataclasses.fields(node):
        v = getattr(node, f.name)
        if dataclasses.is_dataclass(v):
            yield from _nodes(v)


def test_every_field_is_declared():
    """Each node class declares a constraint for every field that is not a nested node."""
    classes = {type(n) for n in _nodes(C.RunConfig())} | {C.RealConfig, C.RealExperimentConfig}
    assert len(classes) >= 26
    for cls in classes:
        assert constraints.unchecked_fields(cls) == [], cls.__name__
        assert cls._path or cls is C.RunConfig, cls.__name__


def test_config_package_imports_no_heavy_module():
    code = ("import relaff_jax.config, sys; "
            "assert 'jax' not in sys.modules and 'sklearn' not in sys.modules and 'mujoco' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
