"""examples/scaled_learners.py: each scaled learner predicts what the scikit-learn pipeline it
stands for predicts, and passes the learner check at the protocol's smallest training set."""
import sys

import numpy as np
import pytest
from sklearn.linear_model import LogisticRegression
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from helpers import ROOT
from relaff_jax.learn.learners import check_learner

sys.path.insert(0, str(ROOT / "examples"))
import scaled_learners as S  # noqa: E402


@pytest.mark.parametrize("n", [2, 7, 50])
def test_scaled_learners_are_the_pipelines(n):
    rng = np.random.default_rng(n)
    X = rng.normal(size=(n, 24)).astype(np.float32) * np.r_[np.full(18, 5.0), np.ones(6)]
    y = np.arange(n) % 2 == 0
    Xt = rng.normal(size=(200, 24)).astype(np.float32)
    got = S.ScaledLogisticRegression(C=0.5, random_state=3).fit(X, y).predict(Xt)
    want = make_pipeline(StandardScaler(), LogisticRegression(C=0.5, max_iter=1000, random_state=3)).fit(X, y).predict(Xt)
    np.testing.assert_array_equal(got, want)
    got = S.ScaledKNeighbors().fit(X, y).predict(Xt)
    np.testing.assert_array_equal(got, make_pipeline(StandardScaler(), KNeighborsClassifier(1)).fit(X, y).predict(Xt))
    # scaling changes the answer where the columns' scales differ: not the bare learner
    bare = KNeighborsClassifier(1).fit(X, y).predict(Xt)
    assert n == 2 or not np.array_equal(got, bare)


def test_scaled_learners_pass_the_learner_check():
    check_learner("scaled_learners.ScaledLogisticRegression", {"max_iter": 200})
    check_learner("scaled_learners.ScaledKNeighbors", {"n_neighbors": 1})
