"""The progress line of `relaff reproduce` and its time estimate (hand-worked cases)."""
import io

import pytest

from relaff_jax.reproduce.progress import TRUST_AFTER, Progress, fmt_time, stage_left

EST = {"generate": 100.0, "features": 50.0, "experiment": 30.0, "report": 20.0}


def test_fmt_time():
    assert fmt_time(59.4) == "0:59"
    assert fmt_time(3725) == "1:02:05"
    assert fmt_time(None) == "--:--"
    assert fmt_time(float("nan")) == "--:--"


def test_stage_left_before_progress_is_the_cost_model():
    # 40 s of a 100 s stage spent, nothing measured: 60 s left
    assert stage_left(100.0, 40.0, 0.0, None, 1000.0) == pytest.approx(60.0)
    # overran the model: never below a tenth of the model's remainder
    assert stage_left(100.0, 400.0, 0.0, None, 1000.0) == pytest.approx(10.0)


def test_stage_left_trusts_the_measured_rate_gradually():
    # progress moved from 10 % at t = 0 to 10 % + TRUST_AFTER at t = 50: fully measured
    f = 0.1 + TRUST_AFTER
    measured = 50.0 * (1 - f) / TRUST_AFTER
    assert stage_left(100.0, 60.0, f, (0.0, 0.1), 50.0) == pytest.approx(measured)
    # half way to TRUST_AFTER: the mean of the model's and the measured estimate
    f = 0.1 + TRUST_AFTER / 2
    measured = 50.0 * (1 - f) / (TRUST_AFTER / 2)
    model = max(100.0 * (1 - f) - 60.0, 100.0 * (1 - f) * 0.1)
    assert stage_left(100.0, 60.0, f, (0.0, 0.1), 50.0) == pytest.approx((measured + model) / 2)


def test_eta_does_not_jump_when_the_first_percent_is_fast_or_slow():
    """The reported jump (17:54, then 1:51:28, then 25:02): extrapolating the rate since
    progress first moved, from the first percent on, moved the ETA by 7x here; the blend
    keeps it within 2x (a 100 s stage, progress first moved at 1 % at t = 0)."""
    first = (0.0, 0.01)
    steps = ((6.0, 0.02), (30.0, 0.021), (60.0, 0.15))
    old = [t * (1 - f) / (f - first[1]) for t, f in steps]  # the former estimate
    new = [stage_left(100.0, t, f, first, t) for t, f in steps]
    assert max(old) / min(old) > 7
    assert max(new) / min(new) < 2
    p = Progress(EST, enabled=False)
    p.begin("generate", None)
    p.fraction, p._first = 0.15, (p.stage_t0, 0.01)
    assert p.eta() >= sum(EST[s] for s in ("features", "experiment", "report"))


def test_line_and_messages():
    buf = io.StringIO()
    p = Progress(EST, stream=buf, every=1e9)
    p.begin("features", lambda: 0.25)
    p.set("pull (3/9)")
    p.tick()
    line = buf.getvalue().strip()
    assert line.startswith("reproduce [2/4 features] pull (3/9)  25% |")
    assert "ETA" in line
    p.tick()  # nothing changed: no new line (not a terminal)
    assert buf.getvalue().count("\n") == 1
    p.begin("report", None)
    assert p.eta() == pytest.approx(20.0, abs=0.5)  # no progress yet: the cost model
    p.message("report: done")
    assert buf.getvalue().endswith("report: done\n")


def test_generation_estimate_follows_the_engine():
    """The cost model's generate stage scales with the engine's rollouts/s; nothing else moves."""
    from relaff_jax.reproduce.progress import COST, estimate_seconds
    from relaff_jax.config import preset, resolve

    mjx = estimate_seconds(resolve(preset("quick"), {"dataset.engine": "mjx"}), 2, 2)
    native = estimate_seconds(preset("quick"), 2, 2)  # the quick preset's default engine
    assert preset("quick").dataset.engine == "native"
    sim = 9 * 100 * COST["rollouts_per_sample"]
    assert mjx["generate"] - COST["sim_compile"] == pytest.approx(sim / COST["rollouts_per_s"])
    assert native["generate"] - COST["sim_compile"] == pytest.approx(sim / COST["rollouts_per_s_native"])
    assert {k: v for k, v in mjx.items() if k != "generate"} == {k: v for k, v in native.items() if k != "generate"}
    # the feasible population selects from about twice the rollouts per sample
    feasible = estimate_seconds(resolve(preset("quick"), {"dataset.population": "feasible", "dataset.engine": "mjx"}),
                                2, 2)
    assert feasible["generate"] - COST["sim_compile"] == pytest.approx(
        9 * 100 * COST["rollouts_per_sample_feasible"] / COST["rollouts_per_s"])


def test_the_paper_presets_estimate_by_hand():
    """The paper preset with the native engine, stage by stage from COST by hand; the workers
    divide the experiment stage alone, up to the CPUs there are. (How close the model comes to
    a measured run is a benchmark figure, docs/reproduce.md, not something a test can know.)"""
    from relaff_jax.learn import forests_per_space
    from relaff_jax.reproduce.progress import COST, estimate_seconds
    from relaff_jax.config import preset, resolve

    cfg = resolve(preset("paper"), {"dataset.engine": "native"})
    est = estimate_seconds(cfg, 2, 2)
    fits = sum(forests_per_space(cfg.experiment, 9, s) for s in ("pca", "rhf"))
    assert est["generate"] == pytest.approx(COST["sim_compile"] + 90_000 * 5.0 / 150.0)
    assert est["features"] == pytest.approx(COST["feature_compile"] + 90_000 / 110.0)
    assert est["experiment"] == pytest.approx(fits * COST["cpu_s_per_fit_compiled"] / 2)
    assert est["report"] == pytest.approx(fits * COST["report_s_per_forest"] + 9 * 2 * COST["report_per_example"])
    one, four = estimate_seconds(cfg, 1, 2), estimate_seconds(cfg, 4, 2)
    assert one["experiment"] == pytest.approx(2 * est["experiment"])
    assert four["experiment"] == pytest.approx(est["experiment"])  # two CPUs: two workers at most
    assert {k: v for k, v in one.items() if k != "experiment"} == {k: v for k, v in est.items() if k != "experiment"}
    # the report's floor holds for a small sweep
    assert estimate_seconds(preset("tiny"), 2, 2)["report"] >= COST["report_fixed"]


def test_sweep_progress_weighs_blocks_by_their_forests_cost(tmp_path):
    """Blocks of large n and of the wide RHF state count for more of the fraction, so the ETA
    does not rise when they come after the cheap ones; every block and prep written is 1."""
    from relaff_jax.config.experiment import ExperimentConfig
    from relaff_jax.learn.status import forest_cost_ms, sweep_progress

    cfg = ExperimentConfig(sizes=(2, 10, 50, 100), sizes_per_block=2, reps_pca=2, reps_rhf=2)
    acts, spaces = ["lift", "pull"], ("pca", "rhf")
    assert forest_cost_ms(100, 318) > forest_cost_ms(100, 18) > forest_cost_ms(2, 18)

    def touch(space, name):
        (tmp_path / space / "blocks").mkdir(parents=True, exist_ok=True)
        (tmp_path / space / "blocks" / name).write_bytes(b"")

    assert sweep_progress(tmp_path, cfg, 2, spaces) == 0.0
    touch("pca", "lift_r000_c00.npz")
    small = sweep_progress(tmp_path, cfg, 2, spaces)
    (tmp_path / "pca" / "blocks" / "lift_r000_c00.npz").unlink()
    touch("pca", "lift_r000_c01.npz")
    large = sweep_progress(tmp_path, cfg, 2, spaces)
    assert 0 < small < large  # sizes 50 and 100 cost more than 2 and 10
    touch("rhf", "lift_r000_c01.npz")
    assert sweep_progress(tmp_path, cfg, 2, spaces) - large > large  # the RHF block outweighs the PCA one
    for s in spaces:
        (tmp_path / s / "prep.npz").write_bytes(b"")
        for t in acts:
            for r in range(2):
                for c in range(2):
                    touch(s, f"{t}_r{r:03d}_c{c:02d}.npz")
    assert abs(sweep_progress(tmp_path, cfg, 2, spaces) - 1.0) < 1e-12
