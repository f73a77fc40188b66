"""The paper's open choices as readings (issue 44): each reading changes what it should and
nothing else; the extra statistics on hand-worked cases."""
import numpy as np
import pytest

from relaff_jax import learn as L
from relaff_jax.config import override

TINY = {
    "sizes": (2, 4, 10, 25), "reps_pca": 2, "reps_rhf": 1, "test_size": 60, "source_size": 60,
    "corr_scenes": 20, "forest.base_trees": 6, "forest.max_trees": 6, "sizes_per_block": 2,
    "online_select": False,
}
ACTS3 = ("lift", "pull", "take")


def tiny_cfg(**kw):
    return override(L.experiment_preset("quick"), dict(TINY, **kw))


@pytest.fixture(scope="module")
def data3():
    return L.synthetic_datasets(200, seed=3, actions=ACTS3)


def test_dbn_repeats_changes_dbn_and_nothing_else(data3, tmp_path):
    runs = {}
    for reading in ("same", "once"):
        cfg = tiny_cfg(dbn_repeats=reading)
        runs[reading] = np.load(L.run_experiment(data3, tmp_path / reading, cfg, ["pca"], seed=2, jobs=1,
                                                 progress=False)["pca"])
    lay = L.layout(3, len(tiny_cfg().thresholds))
    dbn = lay["DBn"]
    same, once = runs["same"], runs["once"]
    others = [c for c in range(lay["n"]) if c != dbn]
    np.testing.assert_array_equal(same["acc"][:, others], once["acc"][:, others])
    np.testing.assert_array_equal(same["correct"][:, others], once["correct"][:, others])
    assert not np.array_equal(same["correct"][:, dbn], once["correct"][:, dbn])  # 12 inputs against 2
    np.testing.assert_array_equal(same["corr"], once["corr"])


def test_dbn_repeats_learner_count(data3):
    cfg = tiny_cfg(dbn_repeats="once")
    # with two actions DBn's one input is DB1's: the same learner only where it is repeated as often
    plan = L.condition_plan(["lift", "pull"], 0, np.eye(2), cfg, "pca")
    from relaff_jax.learn.protocol import condition_repeats

    assert L.block_fits(plan, 1, repeats=condition_repeats(plan, tiny_cfg(), "pca", 2)) < \
        L.block_fits(plan, 1, repeats=condition_repeats(plan, cfg, "pca", 2))


def test_robustness_rows_hand_worked():
    from relaff_jax.report.robustness import robustness_rows, robustness_table

    def f(fid, verdict, est, lo, hi):
        return {"id": fid, "finding": fid.upper(), "verdict": verdict,
                "claims": [{"estimate": est, "interval": [lo, hi]}]}

    readings = {"a": [f("x", "reproduced", 1.0, 0.9, 1.1), f("y", "reproduced", 2.0, 1.5, 2.5)],
                "b": [f("x", "reproduced", 1.2, 1.0, 1.4), f("y", "undecided at this scale", 1.0, 0.5, 1.5)],
                "c": [f("x", "reproduced", 0.8, 0.7, 0.9), f("y", "not reproduced", 0.2, 0.1, 0.3)]}
    rows = {r["id"]: r for r in robustness_rows(readings)}
    assert rows["x"]["survives"] == "yes"
    assert rows["y"]["survives"] == "no: only in a"
    assert rows["y"]["cells"]["c"] == ("not reproduced", "0.20 [0.10, 0.30]")
    header, body = robustness_table(readings)
    assert header == ["finding", "a", "b", "c", "reproduced in every reading"]
    assert body[1][2] == "**undecided at this scale**: 1.00 [0.50, 1.50]"
