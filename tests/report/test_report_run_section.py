"""The report's run section (report/sections.py) reads the machine record of the run log."""


def test_report_names_the_blas_kernels_of_the_run_log():
    """The report's run section names the BLAS kernels the run log recorded, and a log from
    before they were recorded gives the machine line alone."""
    from relaff_jax.report.sections import run_blocks

    m = {"cpu_model": "AMD EPYC", "cpus": 2, "machine": "x86_64", "isa": ["avx2"], "platform": "Linux",
         "blas": [{"internal_api": "openblas", "version": "0.3.30", "architecture": "SkylakeX"}]}
    items = run_blocks({"preset": "tiny", "seed": 0, "machine": m})[1][1]
    assert "BLAS kernels: openblas 0.3.30 SkylakeX" in items
    old = {k: v for k, v in m.items() if k != "blas"}
    items = run_blocks({"preset": "tiny", "seed": 0, "machine": old})[1][1]
    assert any(i.startswith("machine: AMD EPYC") for i in items) and not any("BLAS" in i for i in items)
