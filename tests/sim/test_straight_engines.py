"""The engines apply the straight tcp segments (programs v2): MJX's ``simulate_fn`` hands the
plan's corrections (``straight.corrections``) to its control loop."""
import jax
import jax.numpy as jnp
import pytest

from relaff_jax.config.action import ActionConfig
from relaff_jax.constants import action_id
from relaff_jax.sim import planning, simulate
from relaff_jax.sim.templates import N_SEGMENTS, N_STEPS

V2 = ActionConfig(programs="v3")  # the templates' N_SEGMENTS layout (v4 adds a dwell segment)
RAKE = action_id("rake")


@pytest.mark.slow  # tracing the whole simulate_fn: ~45 CPU s
def test_mjx_simulate_fn_hands_the_corrections_to_the_control_loop(monkeypatch):
    """Traced, not compiled: the corrections ``make_simulate_fn`` passes per scene (v2: one
    (P - 1, 6) block per segment)."""
    seen = {}

    def spy(*args, **kw):
        seen["corr"] = kw.get("corr", args[14] if len(args) > 14 else None)
        d, observe = args[5], args[10]
        return d, jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (N_STEPS,) + x.shape), observe(d))

    monkeypatch.setattr(simulate, "run_program_locked", spy)
    b, nw = 2, N_SEGMENTS + 1
    plan = planning.Plan(jax.ShapeDtypeStruct((b, nw, 6), jnp.float32), jax.ShapeDtypeStruct((b, nw), jnp.float32),
                         jax.ShapeDtypeStruct((N_SEGMENTS,), jnp.int32), jax.ShapeDtypeStruct((b,), bool),
                         jax.ShapeDtypeStruct((b, 3), jnp.float32), jax.ShapeDtypeStruct((b,), jnp.float32))
    args = (jnp.int32(RAKE), jax.ShapeDtypeStruct((b,), jnp.int32), jax.ShapeDtypeStruct((b, 14), jnp.float32),
            jax.ShapeDtypeStruct((b, 12), jnp.float32), plan, jax.ShapeDtypeStruct((b,), bool))
    jax.eval_shape(simulate.make_simulate_fn(V2), *args)
    assert seen["corr"] is not None and seen["corr"].shape == (N_SEGMENTS, V2.straight_pieces - 1, 6)
