"""``planning.setup`` is an lru cache of four configs that jits its own IK: a function traced
after other configs evicted its config's setup must not call it (inside a trace the IK's
result is a tracer and its reachability check fails). Found when a test file cycling through
five configs ran before tests/sim/test_actions.py, whose MJX programs were traced after."""
import jax
import jax.numpy as jnp
import numpy as np

from relaff_jax.config.action import ActionConfig
from relaff_jax.sim import planning, simulate


def test_initial_data_traces_without_calling_setup(monkeypatch):
    cfg = ActionConfig()
    st = planning.setup(cfg)
    want = planning.home_grip(cfg)

    def evicted(*args, **kwargs):
        raise AssertionError("planning.setup called while tracing")

    monkeypatch.setattr(planning, "setup", evicted)
    ctrl = jax.jit(lambda aid, q, v: simulate.initial_data(st, cfg, aid, q, v).ctrl)(
        jnp.int32(0), jnp.asarray(np.asarray(st.world.mj_model.qpos0)[:14], jnp.float32), jnp.zeros(12, jnp.float32))
    assert ctrl.shape == (st.world.mj_model.nu,)
    np.testing.assert_array_equal(planning.home_grip(cfg, st.arm), want)
