"""The real study's folder layout, named once (``relaff real study --out OUT``)::

    OUT/sim/                          the simulated relation data (``sim_relations.py``):
        sim_relations.json            its guard (sensor + config), written before any chunk
        chunk_XXXXX.npz               the simulated chunks, one atomic file each
    OUT/sensor.json                   the training folder's mean pose, the simulated sensor
    OUT/real_features.npz             the training folder's real features (cached)
    OUT/real_features_test.npz        the test folder's (with --test)
    OUT/raw_<space>.npz               the within-folder experiments' raw accuracies
    OUT/raw_<space>_cross.npz         the across-folder ones (with --test)
    OUT/fig14_<space>[_cross].png     box plots, paper Fig. 14 (``report.py``)
    OUT/fig15_<space>[_cross].png     bootstrap curves, paper Fig. 15
    OUT/results.json, results.md      the summaries and the document (``report.py``)
    OUT/relaff_config.json            the tree the study ran with (``provenance.record_config``)
"""
from __future__ import annotations

SIM = "sim"
GUARD = "sim_relations.json"
CHUNK_GLOB = "chunk_*.npz"
SENSOR = "sensor.json"
REAL_FEATURES = "real_features.npz"
REAL_FEATURES_TEST = "real_features_test.npz"
RESULTS_JSON = "results.json"
RESULTS_MD = "results.md"


def chunk(index: int) -> str:
    """A simulated chunk's file name in the ``SIM`` folder."""
    return f"chunk_{index:05d}.npz"


def raw(space: str, cross: bool = False) -> str:
    """The raw accuracies of one space's experiments, within the folder or across folders."""
    return f"raw_{space}{'_cross' if cross else ''}.npz"


def figure(number: int, space: str, cross: bool = False) -> str:
    """``fig14_<space>.png`` or ``fig15_<space>_cross.png``."""
    return f"fig{number}_{space}{'_cross' if cross else ''}.png"


__all__ = ["SIM", "GUARD", "CHUNK_GLOB", "SENSOR", "REAL_FEATURES", "REAL_FEATURES_TEST", "RESULTS_JSON",
           "RESULTS_MD", "chunk", "raw", "figure"]
