"""The forest's declared constraints (``config.experiment.SKLEARN_FOREST``, written out without
scikit-learn) accept and refuse what scikit-learn's own ``_parameter_constraints`` do."""
from __future__ import annotations

import pytest

from relaff_jax.config.experiment import MAX_SAMPLES_FRACTION, SKLEARN_FOREST

PROBES = [None, True, False, 0, 1, 2, 200, -1, 0.0, 0.3, 0.5, 1.0, 1.5, -0.5, "sqrt", "log2", "gini", "entropy",
          "log_loss", "foo", "", float("nan")]


@pytest.mark.parametrize("key", sorted(SKLEARN_FOREST))
def test_forest_constraints_match_sklearn(key):
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.utils._param_validation import InvalidParameterError, validate_parameter_constraints

    cons = RandomForestClassifier._parameter_constraints
    for v in PROBES:
        try:
            validate_parameter_constraints({key: cons[key]}, {key: v}, caller_name="forest")
            theirs = True
        except InvalidParameterError:
            theirs = False
        if isinstance(v, bool) and key != "bootstrap":
            theirs = False  # a boolean is never a count or a fraction here (scikit-learn: an int)
        if key == "max_samples" and isinstance(v, float) and v > MAX_SAMPLES_FRACTION:
            theirs = False  # capped here (documented on the constraint)
        ours = SKLEARN_FOREST[key].problem(v) is None
        assert ours == theirs, (key, v, ours, theirs)
