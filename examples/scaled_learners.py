"""Learner plugins: scikit-learn classifiers behind a StandardScaler, for the learner study.

The states are not standardised (PCA's columns and the repeated 0/1 bootstrap inputs have
different scales), which a linear model's penalty and a distance feel and a tree does not. Each
class here is one scikit-learn ``Pipeline(StandardScaler(), CLASSIFIER)`` under an import path
``experiment.learner`` can name (a pipeline object itself has none)::

  PYTHONPATH=examples relaff experiment ... --set experiment.learner=scaled_learners.ScaledLogisticRegression \\
                                            --set 'experiment.learner_params={"max_iter": 1000}'

The scaler is fitted on each training set alone (2..50 samples in the study), so a constant
column keeps its values (scikit-learn's scale 1 for zero variance).
"""
from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.linear_model import LogisticRegression
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler


class _Scaled(ClassifierMixin, BaseEstimator):
    def _inner(self):
        raise NotImplementedError

    def fit(self, X, y):
        self.pipe_ = make_pipeline(StandardScaler(), self._inner()).fit(np.asarray(X), np.asarray(y))
        self.classes_ = self.pipe_.classes_
        return self

    def predict(self, X):
        return self.pipe_.predict(np.asarray(X))


class ScaledLogisticRegression(_Scaled):
    """``make_pipeline(StandardScaler(), LogisticRegression(C, max_iter, random_state))``."""

    def __init__(self, C: float = 1.0, max_iter: int = 1000, random_state=None):
        self.C, self.max_iter, self.random_state = C, max_iter, random_state

    def _inner(self):
        return LogisticRegression(C=self.C, max_iter=self.max_iter, random_state=self.random_state)


class ScaledKNeighbors(_Scaled):
    """``make_pipeline(StandardScaler(), KNeighborsClassifier(n_neighbors))``."""

    def __init__(self, n_neighbors: int = 1):
        self.n_neighbors = n_neighbors

    def _inner(self):
        return KNeighborsClassifier(n_neighbors=self.n_neighbors)
