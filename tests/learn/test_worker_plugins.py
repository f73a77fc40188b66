"""Worker processes know the driver's plugin actions: ``run_parallel`` over joblib workers (fresh
processes) runs calls that read a user action's spec (its state order, as the prep's source
predictors do) the same as the driver does; a reused worker holds the driver's plugins and no
earlier driver's; a plugin file changed since the driver read it is one error."""
import importlib

import numpy as np
import pytest

from relaff_jax import plugins
from relaff_jax.errors import UserError
from relaff_jax.learn import conditions as C
from relaff_jax.learn.parallel import run_parallel
from relaff_jax.learn.states import manipulated_first_order

R = importlib.import_module("relaff_jax.sim.actions.registry")

PLUGIN = '''
from relaff_jax.sim.actions import ActionSpec, register_action


def targets(s):
    raise AssertionError("not traced here")


def goal(cfg, r):
    raise AssertionError("not traced here")


register_action(ActionSpec(name="nudge_w", pairing="toy+base", segments=((10, 0, False),), targets=targets,
                           goal=goal, grasp="none", manipulates="toy"))
'''


@pytest.fixture
def plugin(tmp_path):
    f = tmp_path / "nudge_plugin.py"
    f.write_text(PLUGIN)
    plugins.load_file(f)
    yield f
    R.unregister("nudge_w")
    plugins._LOADED.pop(f"file {f.resolve()}", None)


def test_workers_read_the_driver_s_user_action(plugin):
    calls = [(manipulated_first_order, (a,), {}) for a in ("nudge_w", "lift", "nudge_w")]
    got = run_parallel(calls, 2, False, total=3, desc="t", unit="call")
    here = [manipulated_first_order(a) for a in ("nudge_w", "lift", "nudge_w")]
    for g, h in zip(got, here):
        np.testing.assert_array_equal(g, h)
    np.testing.assert_array_equal(got[0][:9], np.arange(9))  # declared: the toy first


def test_a_plugin_changed_under_the_run_is_one_error(plugin):
    plugin.write_text(PLUGIN + "\n# changed\n")
    with pytest.raises(UserError, match="the file changed or went away while the run used it"):
        run_parallel([(manipulated_first_order, ("nudge_w",), {})], 2, False, total=1, desc="t", unit="call")


def _origin_of(name):
    return C.registered()[name].origin


def test_a_reused_worker_holds_this_driver_s_plugins_only(tmp_path, monkeypatch):
    """Two plugin files register the same condition name one after the other (the first undone,
    as a test's registry fixture does); the workers, reused, read the second's."""
    monkeypatch.setattr(C, "_REGISTRY", dict(C._REGISTRY))
    origins = []
    for i in range(2):
        f = tmp_path / f"cond_{i}.py"
        f.write_text("from relaff_jax.learn import register_condition\n\n"
                     f"@register_condition('WCOND')\ndef w(k):\n    return k.state[:, :{i + 1}]\n")
        plugins.load_file(f)
        origins.append(f"file {f.resolve()}")
        got = run_parallel([(_origin_of, ("WCOND",), {})] * 3, 2, False, total=3, desc="t", unit="call")
        assert got == [origins[-1]] * 3
        C._REGISTRY.pop("WCOND")  # undone, as the registry fixtures do
    for o in origins:
        plugins._LOADED.pop(o, None)
