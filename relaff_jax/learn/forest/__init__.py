"""The paper's random forests and the three engines that build and evaluate them, bit for bit alike.

Takes states ``X: (N, D)`` float32 and labels ``y: (N,)`` bool with a ``ForestConfig``
(``relaff_jax.config.experiment``); gives fitted forests and their 0/1 predictions.

- ``estimator.py``: the forests as scikit-learn's ``RandomForestClassifier`` (``n_trees``,
  ``make_forest``, ``fit_forest``, ``predict_class``): the reference (engine ``sklearn``);
- ``fit.py``: the same trees from scikit-learn's Cython tree builder without the estimator
  (engine ``fast``, with ``evaluate.py``);
- ``evaluate.py``: exact predictions of many forests on shared test columns in one jitted JAX
  program;
- ``compiled/``: trees and predictions re-expressed in numba, many forests per kernel call
  (engine ``compiled``);
- ``engine.py``: the engine choice (``ForestConfig.engine``) behind ``fit``, ``predict`` and
  ``predict_many``, what the sweep, the source predictors and the categories call.

Nothing is imported here: ``estimator.py`` is read by the learning package's light face (no
scikit-learn until a forest is fitted), the others import scikit-learn, JAX or numba.
"""
