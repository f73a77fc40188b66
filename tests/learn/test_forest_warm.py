"""learn.forest.compiled.warm: it compiles the numba kernels at the argument types the
experiment's own path calls them with (``learners.fit_many`` -> ``engine.fit_many``, then
``engine.predict_many``), so a worker after it loads them and compiles nothing."""
import numpy as np

from relaff_jax.config import preset
from relaff_jax.learn.forest import compiled
from relaff_jax.learn.forest.engine import predict_many
from relaff_jax.learn.learners import fit_many


def test_the_experiments_calls_need_no_kernel_the_warm_up_did_not_compile():
    cfg = preset("quick").experiment.forest
    assert cfg.engine == "compiled"
    compiled.forest.warm(cfg)
    k = compiled.kernels()
    warmed = {name: list(k[name].signatures) for name in ("build_forests", "block_sums")}
    assert all(len(v) == 1 for v in warmed.values())
    rng = np.random.default_rng(3)
    Xs = [rng.normal(size=(n, d)).astype(np.float64) for n, d in ((30, 18), (12, 18))]  # float64, as a user may pass
    ys = [x[:, 0] > 0 for x in Xs]
    forests = fit_many(Xs, ys, [5, 6], cfg)
    ZT = rng.normal(size=(18, 25)).astype(np.float32)
    out = predict_many(forests, ZT, [np.arange(18), np.arange(18)])
    assert out.shape == (2, 25)
    assert {name: list(k[name].signatures) for name in warmed} == warmed
