"""A learner plugin: the nearest class centroid on standardised columns.

Any scikit-learn-compatible classifier is a learner (fit, predict, get_params and a classifier's
tags: ClassifierMixin gives them). Use it with
  relaff experiment ... --set experiment.learner=centroid_learner.CentroidClassifier \\
                        --set 'experiment.learner_params={"shrink": 0.5}'
with this folder on PYTHONPATH (worker processes import the class by its path).
"""
import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin


class CentroidClassifier(ClassifierMixin, BaseEstimator):
    """Predicts the class whose centroid is nearest; ``shrink`` pulls the centroids towards 0."""

    def __init__(self, shrink=0.0):
        self.shrink = shrink

    def fit(self, X, y):
        X, y = np.asarray(X, float), np.asarray(y)
        self.classes_ = np.unique(y)
        self.mean_, self.scale_ = X.mean(0), X.std(0) + 1e-9
        Z = (X - self.mean_) / self.scale_
        self.centroids_ = np.stack([(1 - self.shrink) * Z[y == c].mean(0) for c in self.classes_])
        return self

    def predict(self, X):
        Z = (np.asarray(X, float) - self.mean_) / self.scale_
        d = ((Z[:, None, :] - self.centroids_[None]) ** 2).sum(-1)
        return self.classes_[d.argmin(1)]
