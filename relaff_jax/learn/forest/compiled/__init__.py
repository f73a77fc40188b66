"""The compiled forest engine (``ForestConfig.engine = "compiled"``): scikit-learn 1.9.1's
``RandomForestClassifier`` re-expressed in numba, many forests per kernel call.

Takes forests to fit (``X: (N, D)`` float32, ``y: (N,)`` binary labels, seeds); gives the
same trees as ``RandomForestClassifier(random_state=seed)`` with ``ForestConfig``'s settings
(``Forest``: node arrays equal to each estimator's ``tree_``) and bit-identical
``predict_proba`` and ``predict`` (``tests/learn/test_engine.py``).

- ``rng.py``: numpy's legacy MT19937 (seeding, masked ``randint``) and scikit-learn's ``rand_r``;
- ``split.py``: one node's best split (``node_split_best``, Gini, constant-feature bookkeeping);
- ``build.py``: ``DepthFirstTreeBuilder`` per tree and the loop over the trees of many forests;
- ``evaluate.py``: exact predictions, many forests on shared test columns in one call;
- ``forest.py``: the Python side (``fit_many``, ``fit``, ``predict_proba``, ``predict_block``).

Why numba rather than Cython or C++: the project ships no compiled extension and has no
build step (pure-Python wheel, setuptools); numba compiles on first use, caches on disk and
is one pip dependency with wheels for every platform the project supports, and its loops
read like scikit-learn's Cython, which they are checked against line by line. Importing
this package does not import numba; ``kernels()`` does (and compiles or loads the cache).
"""
from relaff_jax.learn.forest.compiled.forest import Forest, fit, fit_many, kernels, predict_block, predict_labels, predict_proba

__all__ = ["Forest", "fit", "fit_many", "kernels", "predict_block", "predict_labels", "predict_proba"]
