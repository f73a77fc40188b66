"""sim/warm.py: the planner's programs compiled ahead, at the shapes the generation calls them
with (so the generation finds them compiled); unobstruct's toy reach only when it is generated."""
import jax
import numpy as np
import pytest

from relaff_jax.sim import traced_cache as tc
from relaff_jax.sim.reach_screen import PLAN_CHUNK, jitted_parts
from relaff_jax.sim.rollouts import make_batch_prepare_fn
from relaff_jax.sim.templates import ActionConfig
from relaff_jax.sim.warm import placeholder_scenes, planner_warmups

B = 8


def test_the_plan_for_any_generation_and_the_toy_reach_for_unobstruct():
    cfg = ActionConfig()
    assert planner_warmups(cfg, 64, []) == []
    assert len(planner_warmups(cfg, 64, ["lift", "move"])) == 1
    assert len(planner_warmups(cfg, 64, ["unobstruct"])) == 2
    assert len(planner_warmups(cfg, 64, ["lift", "unobstruct"])) == 2


def test_placeholder_scenes_have_the_settled_scenes_dtypes():
    pair, qpos = placeholder_scenes(ActionConfig(), 5)
    assert pair.shape == (5,) and pair.dtype == np.int32 and qpos.shape == (5, 14) and qpos.dtype == np.float32
    assert np.isfinite(qpos).all()


@pytest.mark.slow  # settles and plans unobstruct scenes (the planner's compile)
def test_the_generation_calls_the_warmed_shapes(monkeypatch):
    """Every call the generation makes of the planner's two programs has the shape and dtypes a
    warm-up compiled (batch 8, the programs lane A of the suite compiles): none compiles a
    program of its own."""
    cfg = ActionConfig()
    warm = planner_warmups(cfg, B, ["lift", "unobstruct"])
    assert len(warm) == 2
    seen: list = []
    call = tc._Stored.__call__

    def spy(self, *args):
        if self.name in ("plan_of", "toy_reach"):
            seen.append((self.name, tuple((np.shape(a), str(tc._spec(a).dtype)) for a in args)))
        return call(self, *args)

    monkeypatch.setattr(tc._Stored, "__call__", spy)
    for f in warm:
        f()
    warmed = set(seen)
    rows = min(B, PLAN_CHUNK)
    assert ("toy_reach", (((rows,), "int32"), ((rows, 14), "float32"))) in warmed and len(warmed) == 2
    seen.clear()
    make_batch_prepare_fn("lift", cfg, settle="native")(jax.random.PRNGKey(0), B)
    assert {name for name, _ in seen} == {"plan_of"}, "lift's batch called no plan, or the toy's reach"
    prepare = make_batch_prepare_fn("unobstruct", cfg, settle="native")
    for k in range(40):  # until a batch has a program and a toy the screen cannot rule out
        prepare(jax.random.PRNGKey(k), B)
        if seen[-1][0] == "toy_reach":
            break
    assert {name for name, _ in seen} == {"plan_of", "toy_reach"}, "no batch called unobstruct's toy reach"
    assert set(seen) <= warmed
    plan_fn, reach_fn = jitted_parts(cfg)
    assert len(plan_fn.calls) == 1 and len(reach_fn.calls) == 1  # one compiled shape each
