"""A small experiment protocol shared by the sweep tests: small forests and few sizes keep them
fast (the paper's forest settings are tested in tests/learn/test_learning.py)."""
from relaff_jax import learn as L
from relaff_jax.config import override
from relaff_jax.config.experiment import experiment_preset

TINY = {
    "sizes": (2, 4, 10, 25), "reps_pca": 2, "reps_rhf": 1, "test_size": 60, "source_size": 60,
    "corr_scenes": 20, "forest.base_trees": 6, "forest.max_trees": 6, "sizes_per_block": 2,
    "online_select": False,  # the leave-one-out forests are counted and checked in their own tests
}
ACTS3 = ("lift", "pull", "take")


def tiny_cfg(**kw):
    """The quick preset's protocol at ``TINY``'s sizes, ``kw`` overriding any key."""
    return override(experiment_preset("quick"), dict(TINY, **kw))


def synthetic3():
    """Synthetic datasets of ``ACTS3``, 200 samples each (seed 3)."""
    return L.synthetic_datasets(200, seed=3, actions=ACTS3)
