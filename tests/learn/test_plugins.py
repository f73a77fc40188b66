"""Learners and conditions as plugins: relaff_jax.learn.learners, relaff_jax.learn.conditions.

Checked against scikit-learn fitted directly on the same draws, and against the sweep's own
plan for the built-in conditions; bad learners and plugins are one error line before any work.
"""
import hashlib
import json
import subprocess
import sys

import numpy as np
import pytest

from relaff_jax import learn as L
from relaff_jax.learn.results import load_results
from relaff_jax.learn.sweep import run_experiment
from relaff_jax.config.experiment import experiment_preset, result_differences
from relaff_jax.cli import main
from relaff_jax.config import override
from relaff_jax.constants import ACTIONS
from relaff_jax.errors import UserError
from relaff_jax.learn import conditions as C
from relaff_jax.learn import learners
from relaff_jax.learn import user_conditions as U
from relaff_jax.learn.draws import draw_rep
from relaff_jax.learn.states import augment, state_features
from relaff_jax.provenance import derive_seed

ACTS = ("lift", "pull", "take")
SMALL = {"sizes": (2, 4, 7, 10), "reps_pca": 2, "test_size": 40, "source_size": 40, "corr_scenes": 15,
         "online_select": False, "conditions_pca": ("NB", "DB1")}
ET = "sklearn.ensemble.ExtraTreesClassifier"


@pytest.fixture
def registry(monkeypatch):
    """The condition registry as it was, restored after the test (plugins register globally)."""
    monkeypatch.setattr(C, "_REGISTRY", dict(C._REGISTRY))
    return C._REGISTRY


@pytest.fixture(scope="module")
def data():
    return L.synthetic_datasets(160, seed=5, actions=ACTS)


def _direct_accuracy(est_or_none, X, y, tr, test):
    """A scikit-learn estimator fitted on X[tr] and scored on X[test] (one class: that class)."""
    if np.all(y[tr] == y[tr][0]):  # the protocol's rule for a one-class training set
        pred = np.full(len(test), y[tr][0])
    else:
        pred = est_or_none.fit(X[tr], y[tr]).predict(X[test])
    return np.mean(pred == y[test])


def test_sklearn_learner_curves_equal_scikit_learns_own_fits(data, tmp_path):
    from sklearn.ensemble import ExtraTreesClassifier

    seed = 4
    cfg = override(experiment_preset("quick"), dict(SMALL, learner=ET, learner_params={"n_estimators": 7}))
    path = run_experiment(data, tmp_path / "r", cfg, ["pca"], seed=seed, jobs=1, progress=False)["pca"]
    res, prep = np.load(path), np.load(tmp_path / "r" / "pca" / "prep.npz")
    conds = list(res["conditions"])
    assert json.loads((tmp_path / "r" / "experiment.json").read_text())["config"]["learner"] == ET
    checked = 0
    for ti, t in enumerate(ACTS):
        ds = data[t]
        pool = prep[f"target:{t}"]
        X = state_features(ds["pca"][pool], None, t, "pca")
        y = np.asarray(ds["label"]).astype(bool)[pool]
        # the source predictors are the learner too: fitted on the action's source pool
        src = L.split_pools(len(ds["label"]), ACTIONS.index(t), cfg, seed)["source"]
        sp = ExtraTreesClassifier(n_estimators=7, random_state=derive_seed(seed, 2, 0, ACTIONS.index(t)))
        sp.fit(state_features(ds["pca"][src], None, t, "pca"), np.asarray(ds["label"]).astype(bool)[src])
        for b in ACTS:  # its outputs on every target pool, in its own state order
            pb = prep[f"target:{b}"]
            want = sp.predict(state_features(data[b]["pca"][pb], None, t, "pca")).astype(np.float32)
            np.testing.assert_array_equal(prep[f"boot:{b}"][ti], want)
        for r in range(cfg.reps_pca):
            test, order = draw_rep(y, int(prep[f"test_size:{t}"]), max(cfg.sizes), seed, ACTIONS.index(t), r,
                                   cfg.balanced_test, cfg.balanced_train)
            for si, n in enumerate(cfg.sizes):
                tr = order[:n]
                keys = (seed, 5, 0, ACTIONS.index(t), r, n)
                nb = ExtraTreesClassifier(n_estimators=7, random_state=derive_seed(*keys, 0))
                assert res["acc"][ti, 0, si, r] == _direct_accuracy(nb, X, y, tr, test)
                for s, b in enumerate(ACTS):  # DB1: the state and source s's outputs, repeated 6x
                    if b == t:
                        continue
                    c = conds.index(f"DB1:{b}")
                    Xa = augment(X, prep[f"boot:{t}"][[s]], cfg.repeats_pca)
                    est = ExtraTreesClassifier(n_estimators=7, random_state=derive_seed(*keys, c))
                    assert res["acc"][ti, c, si, r] == _direct_accuracy(est, Xa, y, tr, test)
                    checked += 1
    assert checked == 3 * 2 * 4 * 2
    # a learner that never varies between fits would pass the above trivially: it does vary
    assert len(np.unique(res["acc"][:, 0])) > 2


def test_the_forest_learner_is_the_default_path(data):
    cfg = experiment_preset("quick")
    assert cfg.learner == "forest" and learners.learner_of(cfg) is cfg.forest
    from relaff_jax.config import to_dict
    from relaff_jax.io import jsonable

    stored = jsonable(to_dict(cfg))  # a folder made before learners were plugins lacks both keys
    old = {k: v for k, v in stored.items() if k not in ("learner", "learner_params")}
    assert result_differences(old, cfg) == []
    assert result_differences(stored, override(cfg, {"learner": ET})) == ["learner"]
    assert result_differences(old, override(cfg, {"learner": ET})) == ["learner"]


@pytest.mark.parametrize("sets, says", [
    ({"learner": "sklearn.ensemble.NoSuchForest"}, "has no 'NoSuchForest'"),
    ({"learner": "no_such_pkg.mod.Cls"}, "cannot import module"),
    ({"learner": "sklearn.linear_model.LinearRegression"}, "is not a classifier"),
    ({"learner": ET, "learner_params": {"n_trees": 3}}, "bad experiment.learner_params"),
    ({"learner": ET, "learner_params": {"n_estimators": -1}}, "cannot fit 2 training samples"),
    ({"learner": "sklearn.neighbors.KNeighborsClassifier"}, "n_neighbors"),
    ({"learner": ET, "learner_params": {"random_state": 1}}, "derived from the run's seed"),
    ({"learner_params": {"n_estimators": 5}}, "experiment.forest"),
])
def test_a_bad_learner_is_one_error_before_any_work(sets, says, capsys, tmp_path):
    argv = ["experiment", "--synthetic", "100", "--out", str(tmp_path / "out"), "--space", "pca"]
    for k, v in sets.items():
        argv += ["--set", f"experiment.{k}={json.dumps(v) if not isinstance(v, str) else v}"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(("relaff experiment: error: experiment.learner",  # learn.checks (imports it)
                                                         "relaff experiment: error: config key 'experiment.learner")), err
    assert says in err[0]
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- conditions

def test_built_in_conditions_give_the_plans_columns(data, tmp_path):
    """Each registered built-in, applied to a target's knowledge, gives the columns the sweep's
    plan builds (condition_plan rows, augment): the same conditions by both routes."""
    cfg = override(experiment_preset("quick"), dict(SMALL, conditions_pca=("NB", "DB1", "DBn", "CB1", "CBn"),
                                                       thresholds=(0.0, 0.2, 0.5), cbn_threshold=0.5))
    prep = L.prepare(data, "pca", cfg, seed=2)
    names = L.condition_names(list(ACTS), cfg.thresholds)
    allowed = L.category_allowed(list(ACTS), cfg)
    reg = C.registered()
    assert all(reg[f].builtin for f in ("NB", "DB1", "DBn", "CB1", "CBn"))
    for ti, t in enumerate(ACTS):
        pool = prep[f"target:{t}"]
        X = state_features(data[t]["pca"][pool], None, t, "pca")
        boot = prep[f"boot:{t}"]
        k = U.knowledge(t, list(ACTS), X, boot, prep["corr"], allowed[ti], cfg.repeats_pca, cfg.thresholds)
        got = {}
        for fam in ("NB", "DB1", "DBn", "CB1", "CBn"):
            for name, cols in C.columns(reg[fam], k):
                got[name if ":" in name or fam in ("NB", "DBn") else name] = cols
        plan = L.condition_plan(list(ACTS), ti, prep["corr"], cfg, "pca")
        assert {names[c] for c, _ in plan} == set(got)
        for c, rows in plan:
            want = augment(X, boot[list(rows)], cfg.repeats_pca)[:, X.shape[1]:]
            np.testing.assert_array_equal(got[names[c]], want, err_msg=names[c])


PLUGIN = '''
import numpy as np
from relaff_jax.learn import register_condition


@register_condition("VOTE")
def vote(k):
    """How many other actions' predictors say yes, as a share, and whether any does."""
    s = np.stack(list(k.sources.values()))
    return {"share": s.mean(0)[:, None], "any": s.max(0)[:, None]}
'''


def _cli(args, cwd):
    return subprocess.run([sys.executable, "-m", "relaff_jax.cli", *args], cwd=cwd, capture_output=True, text=True)


def test_a_condition_from_a_file_outside_the_package_runs_through_the_sweep(tmp_path):
    plugin = tmp_path / "my_conditions.py"
    plugin.write_text(PLUGIN)
    out = tmp_path / "res"
    sets = ["--set", 'reproduce.actions=["lift","pull","take"]', "--set", "experiment.sizes=[2,4,10]",
            "--set", "experiment.reps_pca=2", "--set", 'experiment.conditions_pca=["NB","DB1","VOTE"]',
            "--set", "experiment.forest.max_trees=9", "--set", "experiment.forest.base_trees=9"]
    args = ["experiment", "--synthetic", "200", "--out", str(out), "--space", "pca", "--seed", "1", "--jobs", "1",
            "--no-progress", "--plugins", str(plugin), *sets]
    run = _cli(args, tmp_path)
    assert run.returncode == 0, run.stderr
    res, prep = np.load(out / "pca" / "results.npz"), np.load(out / "pca" / "prep.npz")
    conds = list(res["conditions"])
    assert conds[-2:] == ["VOTE:share", "VOTE:any"]
    assert np.all(np.isfinite(res["acc"][:, -2:]))
    meta = json.loads((out / "experiment.json").read_text())
    assert meta["plugins"]["VOTE"]["sha256"] == hashlib.sha256(PLUGIN.encode()).hexdigest()
    assert meta["plugins"]["VOTE"]["origin"].endswith("my_conditions.py")
    # one cell by hand: the paper's forest on the state and the share column, the sweep's seed
    cfg = override(experiment_preset("quick"), {"sizes": (2, 4, 10), "reps_pca": 2, "forest.max_trees": 9,
                                                  "forest.base_trees": 9})
    data = L.synthetic_datasets(200, seed=1, actions=("lift", "pull", "take"))
    t, ti, r, si, n = "pull", 1, 1, 2, 10
    pool = prep[f"target:{t}"]
    X = state_features(data[t]["pca"][pool], None, t, "pca")
    y = np.asarray(data[t]["label"]).astype(bool)[pool]
    share = np.delete(prep[f"boot:{t}"][:3], ti, axis=0).mean(0)[:, None].astype(np.float32)
    test, order = draw_rep(y, int(prep[f"test_size:{t}"]), 10, 1, ACTIONS.index(t), r, True, False)
    c = conds.index("VOTE:share")
    forest = L.fit_forest(np.concatenate([X, share], 1)[order[:n]], y[order[:n]], derive_seed(1, 5, 0, ACTIONS.index(t), r, n, c),
                          cfg.forest)
    pred = L.predict_class(forest, np.concatenate([X, share], 1)[test]).astype(bool)
    assert res["acc"][ti, c, si, r] == np.mean(pred == y[test])
    # the report reads the built-ins as before (the user's conditions follow them on the axis)
    a = L.analyse(load_results(out)["pca"], load_results(out).config, intervals=False)
    assert len(a["conditions"]) == L.layout(3, 3)["n"] + 2
    # the same folder with a changed plugin is another experiment
    plugin.write_text(PLUGIN.replace("s.max(0)", "s.min(0)"))
    again = _cli(args, tmp_path)
    assert again.returncode == 2 and "plugins" in again.stderr, again.stderr


BAD = {
    "missing": (None, "no such file"),
    "nothing": ("import numpy as np\n\ndef vote(k):\n    return k.state[:, :1]\n", "registers no condition"),
    "clash": ("from relaff_jax.learn import register_condition\n\n"
              "@register_condition('DB1')\ndef db1(k):\n    return k.state[:, :1]\n", "clashes with the built-in"),
    "shape": ("from relaff_jax.learn import register_condition\n\n"
              "@register_condition('VOTE')\ndef vote(k):\n    return k.state[1:, :1]\n", "must be an (N, E) numeric array"),
    "rows": ("import numpy as np\nfrom relaff_jax.learn import register_condition\n\n"
             "@register_condition('VOTE')\ndef vote(k):\n    return np.cumsum(k.state[:, :1], axis=0)\n",
             "row i of its columns must depend on scene i only"),
    "unregistered": ("from relaff_jax.learn import register_condition\n\n"
                     "@register_condition('OTHER')\ndef other(k):\n    return k.state[:, :1]\n", "'VOTE'"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_plugin_is_one_error_before_any_work(case, tmp_path, capsys, registry):
    src, says = BAD[case]
    plugin = tmp_path / "plugin.py"
    if src is not None:
        plugin.write_text(src)
    out = tmp_path / "out"
    argv = ["experiment", "--synthetic", "100", "--out", str(out), "--space", "pca", "--plugins", str(plugin),
            "--set", 'experiment.conditions_pca=["NB","DB1","VOTE"]']
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("relaff experiment: error:"), err
    assert says in err[0], err[0]
    assert not out.exists()


def test_register_condition_refuses_bad_names_and_non_functions(registry):
    with pytest.raises(UserError, match="expected a letter"):
        C.register_condition("DB1:x", lambda k: k.state)
    with pytest.raises(UserError, match="not a function"):
        C.register_condition("X", 3)
    C.register_condition("MINE", lambda k: k.state[:, :1])
    with pytest.raises(UserError, match="clashes"):  # a second origin for one name
        C._loading.append(("file elsewhere.py", "0"))
        try:
            C.register_condition("MINE", lambda k: k.state[:, :2])
        finally:
            C._loading.pop()


def test_a_condition_from_an_entry_point_is_registered(registry, monkeypatch):
    import importlib.metadata as md

    ep = md.EntryPoint(name="HALF", value="math:floor", group=C.ENTRY_POINTS)
    bad = md.EntryPoint(name="GONE", value="math:no_such_function", group=C.ENTRY_POINTS)
    monkeypatch.setattr(md, "entry_points", lambda group=None: [ep] if group == C.ENTRY_POINTS else [])
    monkeypatch.setattr(C, "_entry_points_loaded", False)
    assert C.registered()["HALF"].origin == "entry point math:floor"
    monkeypatch.setattr(md, "entry_points", lambda group=None: [bad] if group == C.ENTRY_POINTS else [])
    monkeypatch.setattr(C, "_entry_points_loaded", False)
    monkeypatch.setattr(C, "_REGISTRY", {k: v for k, v in C._REGISTRY.items() if v.builtin})
    with pytest.raises(UserError, match="GONE = math:no_such_function"):
        C.registered()
