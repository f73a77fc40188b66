"""sim/warm.py: unobstruct's screened halves compiled ahead, at the shapes its generation calls
them with (so the generation finds them compiled), and only when unobstruct comes later."""
import jax
import numpy as np
import pytest

from relaff_jax.sim import traced_cache as tc
from relaff_jax.sim.reach_screen import PLAN_CHUNK, jitted_parts
from relaff_jax.sim.rollouts import make_batch_prepare_fn
from relaff_jax.sim.templates import ActionConfig
from relaff_jax.sim.warm import placeholder_scenes, unobstruct_warmups

B = 8


def test_nothing_ahead_when_unobstruct_is_absent_or_first():
    cfg = ActionConfig()
    assert unobstruct_warmups(cfg, 64, ["lift", "move"]) == []
    assert unobstruct_warmups(cfg, 64, ["unobstruct", "lift"]) == []
    assert unobstruct_warmups(cfg, 64, []) == []


def test_placeholder_scenes_have_the_settled_scenes_dtypes():
    pair, qpos = placeholder_scenes(ActionConfig(), 5)
    assert pair.shape == (5,) and pair.dtype == np.int32 and qpos.shape == (5, 14) and qpos.dtype == np.float32
    assert np.isfinite(qpos).all()


@pytest.mark.slow  # settles and plans unobstruct scenes (the planner's compile)
def test_the_generation_calls_the_warmed_shapes(monkeypatch):
    """Every call the generation makes of unobstruct's two halves has the shape and dtypes a
    warm-up compiled (batch 8, the programs lane A of the suite compiles): none compiles a
    program of its own."""
    cfg = ActionConfig()
    warm = unobstruct_warmups(cfg, B, ["lift", "unobstruct"])
    assert len(warm) == 2
    seen: list = []
    call = tc._Stored.__call__

    def spy(self, *args):
        if self.name in ("plan", "toy_reach"):
            seen.append((self.name, tuple((np.shape(a), str(tc._spec(a).dtype)) for a in args)))
        return call(self, *args)

    monkeypatch.setattr(tc._Stored, "__call__", spy)
    for f in warm:
        f()
    warmed = set(seen)
    rows = min(B, PLAN_CHUNK)
    assert warmed == {("plan", (((), "int32"), ((rows,), "int32"), ((rows, 14), "float32"))),
                      ("toy_reach", (((rows,), "int32"), ((rows, 14), "float32")))}
    seen.clear()
    prepare = make_batch_prepare_fn("unobstruct", cfg, settle="native")
    for k in range(40):  # until a batch has scenes screened apart
        prepare(jax.random.PRNGKey(k), B)
        if {name for name, _ in seen} == {"plan", "toy_reach"}:
            break
    assert seen, "no batch called unobstruct's screened halves"
    assert set(seen) <= warmed
    plan_fn, reach_fn = jitted_parts(cfg)
    assert len(plan_fn.calls) == 1 and len(reach_fn.calls) == 1  # one compiled shape each
