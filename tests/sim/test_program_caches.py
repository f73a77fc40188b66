"""The caches of built programs. ``planning.setup`` is an lru cache of four configs that jits
its own IK: a function traced after other configs evicted its config's setup must not call it
(inside a trace the IK's result is a tracer and its reachability check fails; found when a
test file cycling through five configs ran before tests/sim/test_actions.py, whose MJX
programs were traced after). The jitted programs are cached per action list
(``registry.per_action_list``)."""
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


def test_program_caches_are_per_action_list():
    """A user action registered, then removed: the nine's jitted planner is found again (not
    traced anew), while the ten's is another program."""
    import runpy

    from helpers import ROOT
    from relaff_jax.sim import reach_screen, rollouts
    from relaff_jax.sim.actions.registry import action_list_key, names, unregister

    cfg = ActionConfig()
    nine, screen = rollouts.jitted_stage_fns(cfg), reach_screen.jitted_screen_fn(cfg)
    assert action_list_key() == ()
    runpy.run_path(str(ROOT / "examples" / "tenth_action.py"))  # registers "drag"
    try:
        assert names()[-1] == "drag" and [n for n, _ in action_list_key()] == ["drag"]
        ten = rollouts.jitted_stage_fns(cfg)
        assert ten is not nine and ten == rollouts.jitted_stage_fns(cfg)
        assert reach_screen.jitted_screen_fn(cfg) is not screen
    finally:
        unregister("drag")
    assert rollouts.jitted_stage_fns(cfg) is nine and reach_screen.jitted_screen_fn(cfg) is screen
