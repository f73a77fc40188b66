"""benchmarks/label_changes.py: two runs' datasets compared rollout by rollout, on datasets
made from a synthetic rollout function whose second version flips known labels, so every
count is known."""
import json
import sys

import numpy as np

from helpers import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

import label_changes  # noqa: E402
from relaff_jax import data as ds  # noqa: E402
from relaff_jax.config.dataset import DatasetConfig  # noqa: E402


def fn_of(version):
    """Relation from the key; version 2 refuses every 10th program and flips the label of every
    7th executed beside one (placements and relations are the same in both)."""
    def fn(key, b):
        rng = np.random.default_rng(np.asarray(key).tolist())
        rel = rng.integers(0, 3, b)
        label = rng.random(b) < 0.5
        feasible = np.ones(b, bool)
        settled = np.ones(b, bool)
        if version == 2:
            i = np.arange(b)
            feasible = i % 10 != 0
            label = np.where((i % 7 == 0) & (rel == 0), ~label, label) & feasible
            settled = i != 3  # one executed program never at rest
        return {"label": label, "relation": np.asarray(ds.RELATIONS)[rel], "cog_distance": rng.uniform(0.1, 1.0, b),
                "toy": np.full(b, "ball"), "other": np.full(b, "plate"), "feasible": feasible, "settled": settled}
    return fn


def test_counts_and_table(tmp_path, capsys):
    dcfg = DatasetConfig(n_samples=20, rollout_batch=32, distance_bins=2, max_rollouts=64, borrow_fraction=1.0)
    for v in (1, 2):
        ds.generate_dataset(tmp_path / f"r{v}" / "data" / "lift", "lift", fn_of(v), 5, {}, progress=False,
                            dataset_config=dcfg)
    assert label_changes.main([str(tmp_path / "r1"), str(tmp_path / "r2"), "--json", str(tmp_path / "c.json")]) == 0
    d = json.loads((tmp_path / "c.json").read_text())["lift"]
    r1, r2 = (ds.load_rollouts(tmp_path / f"r{v}" / "data" / "lift") for v in (1, 2))
    n = min(len(r1["label"]), len(r2["label"]))
    both = r2["feasible"][:n]
    flipped = both & (r1["label"][:n] != r2["label"][:n])
    s = d["same_placements"]
    assert s["common"] == n and s["both"] == int(both.sum()) == n - len(range(0, n, 10))
    assert s["to_positive"] + s["to_negative"] == int(flipped.sum()) > 0
    assert s["by_relation"] == {"beside": int(flipped.sum()), "on_top": 0, "inside": 0}
    assert d["b"]["unsettled_refused"] == len(range(3, n, 32)) and d["a"]["unsettled_refused"] == 0
    out = capsys.readouterr().out
    assert f"| lift | {n:,} | {n:,} -> {int(both.sum()):,} |" in out
