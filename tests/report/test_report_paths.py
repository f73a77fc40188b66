"""The report stage's default paths give the reference's outputs: the analysis arrays bit for
bit and the report files byte for byte (``write_report(..., reference=True)``: the float copy
of every outcome block, the half curves and the resampled means read apart), on a synthetic
experiment folder of the sweep's layout (``learn.synthetic_results``) with both spaces, RHF
running NB and DB1 only, ties in the online choices and conditions that did not run."""
import numpy as np
import pytest

from relaff_jax.learn import analyse
from relaff_jax.learn.results import load_results
from relaff_jax.config.experiment import ExperimentConfig
from relaff_jax.learn.synthetic_results import write_synthetic_results
from relaff_jax.report.write import write_report

FILES = ("findings.json", "summary.json", "reach.json", "table2.csv", "table2_rhf.csv", "table2.md")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    cfg = ExperimentConfig(sizes=(2, 3, 4, 6, 10, 14, 25, 30), reps_pca=4, reps_rhf=3, test_size=62,
                           ci_resamples=30, keep_outcomes=True)
    return write_synthetic_results(tmp_path_factory.mktemp("syn") / "results", cfg, seed=4)


def _equal(a, b, where=""):
    """Every array, number and string of two analyses the same (NaN where NaN)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _equal(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)) and not isinstance(b, np.ndarray):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _equal(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"), where
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), where
    else:
        assert a == b, where


def test_analysis_same_bits_as_reference(results):
    res = load_results(results)
    for space in ("pca", "rhf"):
        new = analyse(res[space], res.config, seed=3)
        ref = analyse(res[space], res.config, seed=3, reference=True)
        assert new["outcomes"] and np.isfinite(new["table2_ci"]).any()
        _equal(new, ref, space)


def test_report_files_identical_to_reference(results, tmp_path):
    new = write_report(results, tmp_path / "new", examples_per_action=0)
    ref = write_report(results, tmp_path / "ref", examples_per_action=0, reference=True)
    for f in FILES:
        assert (new / f).read_bytes() == (ref / f).read_bytes(), f


def test_comparison_can_fail(results):
    # the check above sees a change in one resampled mean: another seed moves the intervals
    res = load_results(results)
    a = analyse(res["pca"], res.config, seed=3)
    b = analyse(res["pca"], res.config, seed=4)
    with pytest.raises(AssertionError):
        _equal(a, b)
