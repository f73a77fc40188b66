"""The action spec's ``manipulates``: which object a program moves or grasps, first in the state
its predictor learns from. The nine keep their order (paper Table I: the toy for move and take),
a user action's follows its declaration (or the object its grasp holds), a spec written before
the field keeps its hash, and a bad value is one line naming the field."""
import dataclasses
import hashlib
import importlib
import json

import numpy as np
import pytest

from relaff_jax import plugins
from relaff_jax.constants import ACTIONS, PCA_PER_OBJECT
from relaff_jax.errors import UserError
from relaff_jax.learn.states import manipulated_first_order, state_features
from relaff_jax.sim.actions import ActionSpec, register_action

R = importlib.import_module("relaff_jax.sim.actions.registry")  # the module (the package attribute is a function)

SEGMENTS = ((10, 0, False), (10, 1, True))


def _targets(s):  # never traced here: the state order reads the spec only
    raise AssertionError("not called")


def _goal(cfg, r):
    raise AssertionError("not called")


def _user(name, **kw):
    return ActionSpec(name=name, pairing="toy+base", segments=SEGMENTS, targets=_targets, goal=_goal, **kw)


@pytest.fixture
def registered():
    made = []

    def add(spec):
        made.append(spec.name)
        return register_action(spec)

    yield add
    for n in made:
        R.unregister(n)


def test_the_nine_declare_the_paper_order_and_keep_their_states():
    from relaff_jax.sim.actions.builtin import BUILTINS

    toy, other = list(range(PCA_PER_OBJECT)), list(range(PCA_PER_OBJECT, 2 * PCA_PER_OBJECT))
    for s in BUILTINS:
        assert s.manipulates == ("toy" if s.name in ("move", "take") else "other")
        assert R.manipulated(s.name) == s.manipulated == s.manipulates  # the no-JAX reading agrees
        want = toy + other if s.name in ("move", "take") else other + toy  # the order before the field
        np.testing.assert_array_equal(manipulated_first_order(s.name), want)
    assert [s.name for s in BUILTINS] == list(ACTIONS)


def test_a_user_action_s_state_puts_its_declared_object_first(registered):
    registered(_user("nudge_toy", grasp="none", manipulates="toy"))
    registered(_user("hold_toy", grasp="toy"))  # undeclared: the object the grasp holds
    registered(_user("carry_base"))  # undeclared, grasp "other": the base
    registered(_user("carry_base2", manipulates="other", grasp="none"))
    pca = np.random.default_rng(0).normal(size=(5, 18)).astype(np.float32)
    for name, first in (("nudge_toy", "toy"), ("hold_toy", "toy"), ("carry_base", "other"), ("carry_base2", "other")):
        x = state_features(pca, None, name, "pca")
        a, b = (pca[:, :9], pca[:, 9:]) if first == "toy" else (pca[:, 9:], pca[:, :9])
        np.testing.assert_array_equal(x[:, :9], a)
        np.testing.assert_array_equal(x[:, 9:], b)


def _old_hash(s):
    """spec_hash as it was before the field existed (the reference a folder recorded)."""
    fields = {f.name: getattr(s, f.name) for f in dataclasses.fields(s)
              if f.name not in ("targets", "goal", "manipulates")}
    fields["segments"] = [list(x) for x in s.segments]
    fields["targets"] = plugins.source_hash(s.targets)
    fields["goal"] = plugins.source_hash(s.goal)
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()


def test_a_spec_without_the_field_keeps_its_hash_and_a_declared_one_changes_it():
    plain = _user("carry_base")
    assert R.spec_hash(plain) == _old_hash(plain)
    declared = _user("carry_base", manipulates="other")
    assert R.spec_hash(declared) != R.spec_hash(plain)  # a folder records what the spec declared


@pytest.mark.parametrize("kw, message", [
    ({"manipulates": "base"}, "field manipulates: 'base'; valid: toy, other"),
    ({"manipulates": 1}, "field manipulates: 1; valid: toy, other"),
    ({"manipulates": "toy"}, "field manipulates: 'toy', but the closed gripper holds the other object (grasp 'other')"),
    ({"manipulates": "other", "grasp": "toy"}, "field manipulates: 'other', but the closed gripper holds the toy"),
])
def test_a_bad_value_is_one_line_naming_the_field(kw, message):
    with pytest.raises(UserError) as e:
        _user("bad_one", **kw)
    assert str(e.value).startswith("action 'bad_one': ") and message in str(e.value)
    assert "\n" not in str(e.value)
