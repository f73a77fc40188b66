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
