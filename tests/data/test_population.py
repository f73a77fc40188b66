"""Dataset population and negatives: which rollouts a selection may take, how its
negatives are drawn, what the labels consist of (``data.anatomy``).

The rollout function is a synthetic fixture (numpy draws seeded by the chunk key), not
physics, built so that every count is known: stacked pairs are close and positive when
feasible, an infeasible program is always negative (as in the simulator), beside pairs are far.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from relaff_jax import data as ds
from relaff_jax.config.dataset import DatasetConfig
from relaff_jax.errors import UserError
from relaff_jax.cli import main

CFG = {"physics": {"dt": 0.002}}


def reach_rollout_fn(feasible_close_negatives: bool = True, with_feasible: bool = True, with_settled: bool = False):
    """Half the scenes out of reach (label False); stacked pairs at 0.02-0.2 m are positive when
    feasible (except 1 in 5 when ``feasible_close_negatives``); beside pairs at 0.3-1.5 m are
    negative. ``with_settled``: 1 in 5 executed programs ends with its objects still moving
    (``settled`` False), drawn after the rest so the other fields stay the same."""

    def fn(key, b):
        rng = np.random.default_rng(np.asarray(key).tolist())
        rel = rng.integers(0, 3, b)
        stacked = rel > 0
        dist = np.where(stacked, rng.uniform(0.02, 0.2, b), rng.uniform(0.3, 1.5, b))
        feasible = rng.random(b) < 0.5
        fails = (rng.random(b) < 0.2) if feasible_close_negatives else np.zeros(b, bool)
        label = feasible & stacked & ~fails
        out = {"label": label, "relation": np.asarray(ds.RELATIONS)[rel], "cog_distance": dist.astype(np.float32),
               "toy": np.full(b, "ball"), "other": np.full(b, "plate")}
        if with_feasible:
            out["feasible"] = feasible
        if with_settled:  # a program not executed counts as settled (sim.rollouts)
            out["settled"] = ~feasible | (rng.random(b) >= 0.2)
        return out

    return fn


def gen(path, n=40, fn=None, **cfg):
    dcfg = DatasetConfig(**{"max_rollouts": 4000, "distance_bins": 4, "borrow_fraction": 0.0, **cfg},
                         n_samples=n, rollout_batch=32)
    return ds.generate_dataset(path, "lift", fn or reach_rollout_fn(), 5, CFG, progress=False, dataset_config=dcfg)


def test_select_eligible_and_uniform_hand_worked():
    label = np.array([1, 1, 1, 0, 0, 0, 0], bool)
    dist = np.array([1.0, 2.0, 1.5, 1.1, 1.9, 1.2, 9.0])
    ok = np.array([1, 1, 0, 1, 0, 0, 1], bool)
    for seed in range(5):
        sel = ds.select_balanced(label, dist, 4, seed, bins=2, eligible=ok)
        # the only eligible rollouts: positives 0, 1; negatives 3 (in range) and 6 (far)
        assert sel.selected.tolist() == [0, 1, 3, 6]
        assert sel.borrowed == 1
        uni = ds.select_balanced(label, dist, 4, seed, bins=2, eligible=ok, negatives="uniform")
        assert uni.selected.tolist() == [0, 1, 3, 6]
        assert uni.borrowed == 0
        # every rollout eligible: the draws of the selection without the options
        full = ds.select_balanced(label, dist, 4, seed, bins=2, eligible=np.ones(7, bool))
        assert full.selected.tolist() == ds.select_balanced(label, dist, 4, seed, bins=2).selected.tolist()
    assert ds.select_balanced(label, dist, 6, 0, bins=2, eligible=ok) is None  # 2 eligible positives < 3
    with pytest.raises(ValueError, match="negatives must be one of"):
        ds.select_balanced(label, dist, 4, 0, negatives="nearest")


def test_uniform_negatives_match_class_counts_and_ignore_distance():
    rng = np.random.default_rng(0)
    label = rng.random(4000) < 0.3
    dist = np.where(label, rng.uniform(0, 0.2, 4000), rng.uniform(0, 2.0, 4000))
    sel = ds.select_balanced(label, dist, 401, 1, bins=10, negatives="uniform")
    chosen = label[sel.selected]
    assert (chosen.sum(), (~chosen).sum()) == (200, 201) == (sel.n_positive, sel.n_negative)
    # uniform over the negatives: ~90 % lie beyond the positives' 0.2 m (cog would put none there)
    far = (dist[sel.selected][~chosen] > 0.2).mean()
    assert 0.8 < far < 0.97
    assert sel.negative_bin_counts.sum() == (~chosen & (dist[sel.selected] <= sel.bin_edges[-1])).sum()


def test_feasible_population_is_feasible_and_balanced(tmp_path):
    gen(tmp_path / "f", population="feasible")
    r = ds.load_rollouts(tmp_path / "f")
    sel = r["selected"]
    assert sel.sum() == 40
    assert r["label"][sel].sum() == 20
    assert r["feasible"][sel].all()
    assert not r["feasible"].all()  # the population excluded something
    meta = json.loads((tmp_path / "f" / ds.SIDECAR).read_text())
    assert meta["selection_scheme"]["population"] == "feasible"
    assert meta["selection"]["population"] == "feasible"
    assert meta["selection"]["eligible_rollouts"] == int(r["feasible"].sum())
    a = ds.anatomy(tmp_path / "f")
    assert a["selection"]["negatives_infeasible_share"] == 0.0
    assert a["selection"]["feasible"] == 40
    ds.add_features(tmp_path / "f", lambda smp: {"d2": np.asarray(smp["cog_distance"]) * 2}, 8)
    assert ds.load_dataset(tmp_path / "f")["d2"].shape == (40,)
    # resumed with the other population, the folder is selected again from its rollouts and
    # becomes the dataset a run of that population makes from the start (it stops earlier);
    # the old selection's features go with it
    gen(tmp_path / "f", population="all")
    assert not (tmp_path / "f" / "features.json").exists()
    assert "d2" not in ds.load_dataset(tmp_path / "f")
    gen(tmp_path / "all", population="all")
    assert_same_dataset(tmp_path / "f", tmp_path / "all")
    assert json.loads((tmp_path / "f" / ds.SIDECAR).read_text())["selection"]["population"] == "all"
    # and back: the feasible population needs chunks the removal dropped; simulated again
    gen(tmp_path / "f", population="feasible")
    gen(tmp_path / "feas", population="feasible")
    assert_same_dataset(tmp_path / "f", tmp_path / "feas")


def test_a_kill_while_selecting_again_leaves_a_folder_the_rerun_selects(tmp_path, monkeypatch):
    """Killed after one of the chunks past the new stopping point was removed: the rerun
    removes the rest and ends with the dataset a run of the new scheme makes."""
    import relaff_jax.data.generate as G

    gen(tmp_path / "f", population="feasible")
    gen(tmp_path / "all", population="all")
    real_drop = G.drop_chunks
    dropped = []

    def drop_one_then_die(cdir, indices):
        real_drop(cdir, sorted(indices)[-1:])  # the highest first, as drop_chunks does
        dropped.append(len(indices))
        raise KeyboardInterrupt("killed while removing chunks")

    monkeypatch.setattr(G, "drop_chunks", drop_one_then_die)
    with pytest.raises(KeyboardInterrupt):
        gen(tmp_path / "f", population="all")
    assert dropped and dropped[0] > 1  # there were several to remove; one went
    monkeypatch.setattr(G, "drop_chunks", real_drop)
    gen(tmp_path / "f", population="all")
    assert_same_dataset(tmp_path / "f", tmp_path / "all")


def assert_same_dataset(a, b):
    ra, rb = ds.load_rollouts(a), ds.load_rollouts(b)
    assert ra["selected"].tolist() == rb["selected"].tolist()
    assert ra["label"].tolist() == rb["label"].tolist()
    sa, sb = (json.loads((p / ds.SELECTION).read_text()) for p in (a, b))
    assert sa == sb


def test_unsettled_rollouts_are_refused_and_counted(tmp_path):
    fn = reach_rollout_fn(with_settled=True)
    gen(tmp_path / "r", population="feasible", fn=fn)
    r = ds.load_rollouts(tmp_path / "r")
    sel = r["selected"]
    assert sel.sum() == 40 and r["settled"][sel].all() and r["feasible"][sel].all()
    moving = r["feasible"] & ~r["settled"]
    assert moving.sum() > 0  # there was something to refuse
    index = json.loads((tmp_path / "r" / ds.SELECTION).read_text())
    assert index["unsettled"] == "refuse"
    assert index["unsettled_refused"] == int(moving.sum())
    assert index["eligible_rollouts"] == int((r["feasible"] & r["settled"]).sum())
    # kept: the same rollouts, and unsettled ones may be selected (the former behaviour)
    gen(tmp_path / "k", population="feasible", fn=fn, unsettled="keep")
    k = ds.load_rollouts(tmp_path / "k")
    assert (k["selected"] & ~k["settled"]).any()
    assert json.loads((tmp_path / "k" / ds.SELECTION).read_text())["unsettled_refused"] == 0
    # the population "all" refuses only executed programs still moving (unexecuted count as settled)
    gen(tmp_path / "a", fn=fn)
    a = json.loads((tmp_path / "a" / ds.SELECTION).read_text())
    ra = ds.load_rollouts(tmp_path / "a")
    assert a["unsettled_refused"] == int((~ra["settled"]).sum()) == int((ra["feasible"] & ~ra["settled"]).sum())


def test_rollouts_without_a_rest_read_are_all_taken(tmp_path):
    gen(tmp_path / "n", population="feasible")  # the fixture without ``settled``
    index = json.loads((tmp_path / "n" / ds.SELECTION).read_text())
    assert index["unsettled"] == "refuse" and index["unsettled_refused"] is None


def test_all_population_negatives_are_mostly_out_of_reach(tmp_path):
    """Distance matching in miniature: matched negatives are unreachable stacks."""
    gen(tmp_path / "a", n=200)
    a = ds.anatomy(tmp_path / "a")
    s = a["selection"]
    # stacked negatives: 1/2 infeasible + 1/2 * 1/5 failing: 5/6 of them infeasible
    assert 0.7 < s["negatives_infeasible_share"] < 0.95
    assert s["oracle_feasible_acc"] > 0.85 > s["oracle_relation_acc"]
    assert s["oracle_feasible_relation_acc"] >= s["oracle_feasible_acc"]


def test_unmet_matching_is_warned_recorded_and_shown(tmp_path):
    # feasible negatives are all beside (far): cog matching inside the feasible population
    # cannot be met, and the generator stops at match_patience instead of the cap
    fn = reach_rollout_fn(feasible_close_negatives=False)
    with pytest.warns(UserWarning, match=r"matching was not met \(match_patience 2"):
        res = gen(tmp_path / "u", population="feasible", match_patience=2.0, fn=fn)
    assert res["matching_met"] is False
    assert res["borrowed"] == 20
    assert res["rollouts"] < 4000
    idx = json.loads((tmp_path / "u" / ds.SELECTION).read_text())
    assert idx["matching_met"] is False
    assert idx["borrowed_share"] == 1.0
    assert "distance matching NOT met" in ds.format_anatomy(ds.anatomy(tmp_path / "u"))
    assert ds.info(tmp_path / "u")["matching_met"] is False
    assert "NOT met" in ds.format_info(ds.info(tmp_path / "u"))
    # a run killed after two chunks and resumed stops at the same chunk, with the same selection
    calls = []

    def killed(key, b):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(1)
        return fn(key, b)

    with pytest.raises(KeyboardInterrupt):
        gen(tmp_path / "v", population="feasible", match_patience=2.0, fn=killed)
    with pytest.warns(UserWarning, match="matching was not met"):
        again = gen(tmp_path / "v", population="feasible", match_patience=2.0, fn=fn)
    assert again["rollouts"] == res["rollouts"]
    assert again["new_chunks"] == res["chunks"] - 2
    assert json.loads((tmp_path / "v" / ds.SELECTION).read_text())["selected"] == idx["selected"]


def test_population_needs_the_feasible_field(tmp_path):
    with pytest.raises(ds.DatasetError, match="no 'feasible' field"):
        gen(tmp_path / "m", fn=reach_rollout_fn(with_feasible=False), population="feasible")
    with pytest.raises(UserError, match="'dataset.population' must be one of all, feasible"):
        gen(tmp_path / "m2", population="reachable")


def test_anatomy_hand_made():
    label = np.array([1, 1, 1, 0, 0, 0, 0, 0], bool)
    feasible = np.array([1, 1, 1, 1, 0, 0, 0, 1], bool)
    relation = np.array(["on_top", "on_top", "inside", "beside", "on_top", "on_top", "beside", "beside"])
    dist = np.array([0.1, 0.2, 0.05, 1.0, 0.1, 0.3, 2.0, 0.5])
    selected = np.array([1, 1, 0, 1, 1, 1, 0, 0], bool)
    a = ds.anatomy_of(label, feasible, relation, dist, selected)
    s, r = a["selection"], a["rollouts"]
    assert (s["n"], s["positives"], s["feasible"]) == (5, 2, 3)
    assert s["negatives_infeasible_share"] == pytest.approx(2 / 3)
    assert r["negatives_infeasible_share"] == pytest.approx(3 / 5)
    assert s["oracle_feasible_acc"] == pytest.approx(4 / 5)
    assert s["oracle_relation_acc"] == pytest.approx(3 / 5)  # on_top's 2 of 4 is a tie: negative
    assert s["oracle_feasible_relation_acc"] == 1.0
    assert r["cells"]["feasible|on_top"] == {"n": 2, "positives": 2, "label_rate": 1.0}
    assert r["cells"]["feasible|beside"] == {"n": 2, "positives": 0, "label_rate": 0.0}
    assert r["cells"]["infeasible|inside"] == {"n": 0, "positives": 0, "label_rate": None}
    assert s["distance_quantiles"]["positives"] == pytest.approx(np.quantile([0.1, 0.2], [0.1, 0.5, 0.9]).tolist())


def test_anatomy_command(tmp_path, capsys):
    gen(tmp_path / "c")
    assert main(["anatomy", str(tmp_path / "c"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["population"] == "all"
    assert d["selection"]["n"] == 40
    assert main(["anatomy", str(tmp_path / "c")]) == 0
    assert "label = feasible" in capsys.readouterr().out


def test_report_reach_section(tmp_path):
    from relaff_jax.report.reach import reach_blocks, reach_figure

    gen(tmp_path / "lift", n=200)
    anat = {"lift": ds.anatomy(tmp_path / "lift")}
    assert reach_figure(anat, tmp_path / "fig_reach.png").stat().st_size > 1000
    blocks = reach_blocks(anat, {"take": "no 'feasible' field"}, tmp_path)
    table = next(b for b in blocks if b[0] == "table")
    s = anat["lift"]["selection"]
    # the fixture has no rest read: "refuse" with nothing known to refuse ("-")
    assert table[2][0][:5] == ["lift", "all", "cog", "refuse (-)", 200]
    assert table[2][0][6] == f"{100 * s['negatives_infeasible_share']:.0f} %"
    assert any(b[0] == "img" for b in blocks)
    assert any("take (no 'feasible' field)" in str(b) for b in blocks)
