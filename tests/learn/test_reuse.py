"""``--reuse``: another reading's experiment gives every condition whose learner is unchanged;
the results equal a run that fits everything."""
import numpy as np
import pytest

from helpers.experiments import synthetic3, tiny_cfg
from relaff_jax.errors import UserError
from relaff_jax.learn import folder as F
from relaff_jax.learn.reuse import refit, signatures
from relaff_jax.learn.sweep import run_experiment

NOT_RESULTS = ("seconds", "seconds_prep", "new_fits")


def cfg_of(**kw):
    """The small protocol with the online choice's leave-one-out forests (a learner property the reuse compares)."""
    return tiny_cfg(online_select=True, select_size=10, **kw)


@pytest.fixture(scope="module")
def data3():
    return synthetic3()


@pytest.fixture(scope="module")
def runs(data3, tmp_path_factory):
    """Each reading fitted whole, both spaces; the folders are not modified by the tests."""
    base = tmp_path_factory.mktemp("readings")
    for reading in ("same", "once"):
        run_experiment(data3, base / reading, cfg_of(dbn_repeats=reading), ["pca", "rhf"], seed=2, jobs=1,
                       progress=False)
    return base


def _assert_same_results(a, b, space):
    with np.load(F.results(a, space)) as za, np.load(F.results(b, space)) as zb:
        keys = [k for k in za.files if k not in NOT_RESULTS]
        assert sorted(keys) == sorted(k for k in zb.files if k not in NOT_RESULTS)
        for k in keys:
            np.testing.assert_array_equal(za[k], zb[k], err_msg=f"{space}: {k}")
        return int(za["new_fits"]), int(zb["new_fits"])


@pytest.mark.parametrize("want,donor", [("once", "same"), ("same", "once")])
def test_reuse_gives_the_bits_of_a_whole_run(data3, runs, tmp_path, want, donor):
    out = tmp_path / want
    run_experiment(data3, out, cfg_of(dbn_repeats=want), ["pca", "rhf"], seed=2, jobs=1, progress=False,
                   reuse=runs / donor)
    new_pca, whole_pca = _assert_same_results(out, runs / want, "pca")
    new_rhf, whole_rhf = _assert_same_results(out, runs / want, "rhf")
    # PCA refits DBn alone: one learner of 1 + 2 DB1 + DBn + CB1 + CBn's per (target, size, rep)
    n_targets, n_sizes, reps = 3, 4, 2
    assert new_pca == n_targets * n_sizes * reps
    assert whole_pca > 5 * new_pca
    assert new_rhf == 0 and whole_rhf > 0  # RHF runs no DBn: every block is the donor's
    for space in ("pca", "rhf"):  # every block's arrays as the whole run wrote them
        for path in F.block_files(runs / want, space):
            mine = out / space / "blocks" / path.name
            with np.load(path) as za, np.load(mine) as zb:
                for k in za.files:
                    np.testing.assert_array_equal(za[k], zb[k], err_msg=f"{path.name}: {k}")
    assert F.is_complete(out)
    import json
    assert json.loads((out / "experiment.json").read_text())["reused_from"] == str((runs / donor).resolve())


def test_reuse_of_a_partial_donor_fits_what_it_lacks(data3, runs, tmp_path):
    import shutil

    donor = tmp_path / "donor"
    shutil.copytree(runs / "same", donor)
    gone = sorted(F.block_files(donor, "pca"))[:3]
    for p in gone:
        p.unlink()
    (donor / "pca" / "results.npz").unlink()
    out = tmp_path / "once"
    run_experiment(data3, out, cfg_of(dbn_repeats="once"), ["pca"], seed=2, jobs=1, progress=False, reuse=donor)
    new, _ = _assert_same_results(out, runs / "once", "pca")
    assert new > 3 * 4 * 2  # the three missing blocks fitted whole


def test_reuse_refuses_another_experiment(data3, runs, tmp_path):
    with pytest.raises(UserError, match=r"differs in \['seed'\]"):
        run_experiment(data3, tmp_path / "a", cfg_of(dbn_repeats="once"), ["pca"], seed=3, jobs=1, progress=False,
                       reuse=runs / "same")
    with pytest.raises(UserError, match=r"config\.reps_pca"):
        run_experiment(data3, tmp_path / "b", cfg_of(dbn_repeats="once", reps_pca=3), ["pca"], seed=2, jobs=1,
                       progress=False, reuse=runs / "same")
    with pytest.raises(UserError, match="no experiment.json"):
        run_experiment(data3, tmp_path / "c", cfg_of(), ["pca"], seed=2, jobs=1, progress=False, reuse=tmp_path)
    with pytest.raises(UserError, match="output folder itself"):
        run_experiment(data3, runs / "same", cfg_of(), ["pca"], seed=2, jobs=1, progress=False, reuse=runs / "same")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()  # refused before anything is written


def test_refit_hand_worked():
    # three actions, target 0: NB (0), DB1 of 1 (1) and of 2 (2), DBn (3) of both
    plan = [(0, ()), (1, (1,)), (2, (2,)), (3, (1, 2))]
    same = {0: 6, 1: 6, 2: 6, 3: 6}
    once = {0: 6, 1: 6, 2: 6, 3: 1}
    assert refit(plan, once, plan, same, (1, 2)) == {3}
    assert refit(plan, same, plan, same, (1, 2)) == frozenset()
    # two actions: DBn's one input is DB1's; repeated alike they are one learner, seeded by DB1
    plan2 = [(0, ()), (1, (1,)), (3, (1,))]
    sig = signatures(plan2, {0: 6, 1: 6, 3: 6}, (1,))
    assert sig[3] == sig[1] == (((1,), 6), 1, True)
    # once, DBn is its own learner: refit, and DB1's forests (its seed condition unchanged) are not
    assert refit(plan2, {0: 6, 1: 6, 3: 1}, plan2, {0: 6, 1: 6, 3: 6}, (1,)) == {3}
    # the reverse: DBn joins DB1's learner, which is fitted whole (a learner is refitted or read, never split)
    assert refit(plan2, {0: 6, 1: 6, 3: 6}, plan2, {0: 6, 1: 6, 3: 1}, (1,)) == {1, 3}
