"""A user's conditions beside Table II (``learn.user_rows``): on a synthetic experiment folder
whose user learners are copies of DB1's candidates and of DBn, the user rows are the DB1 and
DBn rows bit for bit (values per target, chosen sources and the intervals: the same code and
the same resamples), on the default and the reference paths; a folder without user learners
has no rows."""
import numpy as np
import pytest

from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn import TABLE2_ROWS, analyse, layout
from relaff_jax.learn.results import load_results
from relaff_jax.learn.synthetic_results import write_synthetic_results
from relaff_jax.learn.user_rows import groups, user_rows

AS_DB1 = {"COPY average": "DB1 average", "COPY best": "DB1 best", "COPY best after ten": "DB1 best after ten",
          "COPYN": "DBn"}


def with_copies(folder, space="pca"):
    """Append DB1's candidates as ``COPY:<source>`` and DBn as ``COPYN`` to a results folder
    (accuracies and outcomes copied; no leave-one-out, as for a user's learner)."""
    path = folder / space / "results.npz"
    z = dict(np.load(path))
    lay = layout(len(z["actions"]), len(z["thresholds"]))
    idx = list(lay["DB1"]) + [lay["DBn"]]
    for k in ("acc", "loo", "acc_subset", "correct"):
        extra = np.full_like(z[k][:, idx], np.nan) if k == "loo" else z[k][:, idx]
        z[k] = np.concatenate([z[k], extra], 1)
    z["conditions"] = np.concatenate([z["conditions"], [f"COPY:{a}" for a in z["actions"]] + ["COPYN"]])
    np.savez(path, **z)
    return folder


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    cfg = ExperimentConfig(sizes=(2, 3, 4, 6, 10, 14, 25, 30), reps_pca=4, reps_rhf=3, test_size=62,
                           ci_resamples=30, keep_outcomes=True)
    return write_synthetic_results(tmp_path_factory.mktemp("syn") / "results", cfg, seed=4)


def test_groups_split_the_user_learners_by_condition():
    conds = ["NB", "DB1:a", "V:x", "V:y", "ONE", "W:z"]
    assert groups(conds, 2) == {"V": [2, 3], "ONE": [4], "W": [5]}
    assert groups(conds[:2], 2) == {}


def test_no_user_learner_no_rows(folder):
    res = load_results(folder)
    u = user_rows(res["pca"], res.config, seed=3)
    assert u["names"] == [] and u["best"] == {}


@pytest.mark.parametrize("reference", [False, True])
def test_copies_of_db1_and_dbn_give_their_rows_bit_for_bit(folder, tmp_path, reference):
    import shutil

    copy = with_copies(shutil.copytree(folder, tmp_path / "results"))
    res = load_results(copy)
    a = analyse(res["pca"], res.config, seed=3, reference=reference)
    u = user_rows(res["pca"], res.config, seed=3, reference=reference)
    assert u["names"] == list(AS_DB1) and u["condition"] == ["COPY"] * 3 + ["COPYN"]
    for i, name in enumerate(u["names"]):
        j = TABLE2_ROWS.index(AS_DB1[name])
        for key in ("table2_per_target", "gain_per_target", "per_target_ci"):
            assert np.array_equal(u[key][i], a[key][j], equal_nan=True), (name, key)
        for key in ("table2", "gain", "table2_ci", "gain_ci"):
            assert np.array_equal(u[key][i], a[key][j], equal_nan=True), (name, key)
        assert u["n_targets"][i] == a["n_targets"][j]
    assert np.isfinite(u["table2_ci"]).all() and np.isfinite(u["table2"]).all()  # the check compares numbers
    src = lambda i: a["conditions"][i].split(":")[1]  # noqa: E731
    assert u["best"]["COPY"] == {t: src(i) for t, i in zip(a["actions"], a["best_db1"])}
    assert u["best_after_ten"]["COPY"] == {t: src(i) for t, i in zip(a["actions"], a["ten_db1"])}
