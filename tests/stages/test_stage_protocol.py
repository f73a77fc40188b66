"""The stage layer: every stage module keeps the protocol of ``stages.protocol`` on an empty
and on a partial run folder, and a stage's command and ``reproduce`` reach one function."""
import json

import numpy as np
import pytest

from relaff_jax import cli
from relaff_jax import data as D
from relaff_jax import reproduce as R
from relaff_jax.config import override, to_dict
from relaff_jax.constants import STAGES
from relaff_jax.reproduce.folder import open_log
from relaff_jax.reproduce.run import STAGE_MODULES, bound_hooks
from relaff_jax.config import RunConfig
from relaff_jax.stages import experiment, features, generate, report
from relaff_jax.stages.protocol import Hooks, Paths, Run, Silent, Stage, Status

ACTS = ("lift", "take")
SETTINGS = {"reproduce.actions": ACTS, "dataset.n_samples": 24, "dataset.rollout_batch": 8,
            "dataset.feature_batch": 8}


class Stop(Exception):
    """Raised by a stand-in to end a run at a chosen point."""


def fake_rollouts(action, batch, stop_at_chunk=None):
    """A labelled stand-in simulation: seeded by the chunk key, learnable distances."""
    chunk = [0]

    def fn(key, b):
        chunk[0] += 1
        if stop_at_chunk is not None and chunk[0] >= stop_at_chunk:
            raise Stop(f"{action}: chunk {chunk[0]}")
        rng = np.random.default_rng(np.asarray(key).tolist() + [len(action)])
        rel = rng.integers(0, 3, b).astype(np.int32)
        return {"label": rng.random(b) < 0.5, "relation": rel,
                "cog_distance": rng.uniform(0.05, 0.9, b).astype(np.float32),
                "toy": np.asarray(("ball", "cube"))[rng.integers(0, 2, b)],
                "other": np.asarray(("plate", "cup"))[rng.integers(0, 2, b)]}

    return fn, {"fake": action}, None


def fake_feature_config(seed):
    return {"fake perception": True, "seed": seed}


def fake_features(seed):
    def compute(s):
        n = len(s["label"])
        rng = np.random.default_rng([seed, int(s["rollout"][0])])
        return {"pca": rng.normal(size=(n, 18)).astype(np.float32), "rhf": rng.random((n, 300)).astype(np.float32),
                "unseen": np.zeros((n, 2), bool)}

    return compute, fake_feature_config(seed)


def make_run(root, hooks):
    cfg = override(R.preset("tiny"), SETTINGS)
    paths = Paths(root)
    log = open_log(paths, "tiny", cfg, 3)
    return Run(paths, "tiny", cfg, 3, 1, (), Silent(), *bound_hooks(cfg, hooks), log, {})


def check_statuses(run, want):
    for name, m in STAGE_MODULES.items():
        st, f = m.status(run), m.progress(run)
        assert isinstance(st, Status) and st.state == want[name][0], (name, st)
        assert isinstance(f, float) and want[name][1](f), (name, f)


def test_every_stage_module_keeps_the_protocol(tmp_path):
    assert tuple(STAGE_MODULES) == STAGES
    assert [m.NAME for m in (generate, features, experiment, report)] == list(STAGES)
    for m in STAGE_MODULES.values():
        assert isinstance(m, Stage), m.__name__
    assert not isinstance(Silent(), Stage)  # the check is real: a thing without the functions fails it
    zero = lambda f: f == 0.0  # noqa: E731
    hooks = Hooks(rollout_factory=fake_rollouts, feature_factory=fake_features, feature_config=fake_feature_config)

    # an empty run folder: every stage absent, nothing done
    run = make_run(tmp_path / "empty", hooks)
    check_statuses(run, dict.fromkeys(STAGES, ("absent", zero)))

    # a partial one: lift's dataset finished, take's stopped after its first chunk
    run = make_run(tmp_path / "partial", Hooks(
        rollout_factory=lambda a, b: fake_rollouts(a, b, stop_at_chunk=2 if a == "take" else None),
        feature_factory=fake_features, feature_config=fake_feature_config))
    with pytest.raises(Stop, match="take: chunk 2"):
        generate.run(run, False)
    assert generate.action_status(run, "lift").state == "complete"
    check_statuses(run, {"generate": ("partial", lambda f: 0.5 <= f < 1.0), "features": ("absent", zero),
                         "experiment": ("absent", zero), "report": ("absent", zero)})

    # resumed with the full stand-in: the generate stage completes, then the features stage
    run = make_run(tmp_path / "partial", hooks)
    items = generate.run(run, False)
    assert items["lift"] == {"status": "skipped"} and items["take"]["status"] == "ran"
    assert generate.status(run).state == "complete" and generate.progress(run) == 1.0
    features.run(run, False)
    assert features.status(run) == Status("complete", "2 of 2 complete") and features.progress(run) == 1.0
    assert experiment.status(run).state == "absent"


def test_generate_command_and_reproduce_reach_the_same_stage_function(tmp_path, monkeypatch, capsys):
    """``relaff generate`` (the real parser, in-process) and ``reproduce`` call one
    ``stages.generate.generate_one``; given reproduce's seed for an action, the command writes
    the same dataset, bit for bit."""
    calls = []
    real = generate.generate_one

    def spy(tree, action, out, seed, **kw):
        calls.append((action, seed, tree.dataset.n_samples, tree.dataset.rollout_batch))
        got = real(tree, action, out, seed, **kw)
        if "reproduce" in str(out):
            raise Stop("reproduce reached generate_one")  # its later stages are not the point here
        return got

    monkeypatch.setattr(generate, "generate_one", spy)
    monkeypatch.setattr(generate, "rollout_factory_for", lambda cfg: fake_rollouts)
    seed = R.seeds(3)["datasets"]["lift"]
    # the command given the dataset settings of reproduce's tree (tiny's selection settings as --set)
    tiny, default = to_dict(override(R.preset("tiny"), SETTINGS).dataset), to_dict(RunConfig().dataset)
    sets = [x for k, v in tiny.items() if v != default[k] and k not in ("n_samples", "rollout_batch")
            for x in ("--set", f"dataset.{k}={json.dumps(v)}")]
    assert sets  # tiny's selection differs from the default's: the comparison needs them
    argv = ["generate", "lift", "--samples", "24", "--batch", "8", "--seed", str(seed), "--out", str(tmp_path / "cmd")]
    argv += sets
    assert cli.main(argv) == 0, capsys.readouterr().err
    with pytest.raises(Stop):
        R.reproduce(tmp_path / "reproduce", "tiny", 3, overrides=SETTINGS, jobs=1, progress=False)
    assert calls == [("lift", seed, 24, 8)] * 2
    a, b = D.load_dataset(tmp_path / "cmd"), D.load_dataset(tmp_path / "reproduce" / "data" / "lift")
    assert sorted(a) == sorted(b)
    for k in a:
        np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b[k]), err_msg=k)
    log = json.loads((tmp_path / "reproduce" / R.RUN_LOG).read_text())
    assert log["runs"][-1]["status"].startswith("failed: Stop") and "(in generate)" in log["runs"][-1]["status"]


def test_a_custom_feature_factory_needs_its_config():
    with pytest.raises(R.ReproduceError, match="needs feature_config"):
        Hooks(feature_factory=fake_features)
    assert Hooks(feature_factory=fake_features, feature_config=fake_feature_config).feature_config(2) == \
        fake_features(2)[1]
