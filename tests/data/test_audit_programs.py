"""The audit replays a dataset with the programs it was made with: a v1 dataset records v1 by the
absence of ``programs`` (``templates.stored_config``), which the default (v2) must not fill in."""
from __future__ import annotations

import json

import pytest

from relaff_jax.config.action import ActionConfig
from relaff_jax.data import audit as A
from relaff_jax.data.layout import SIDECAR
from relaff_jax.data.store import FORMAT, FORMAT_VERSION
from relaff_jax.report.audit import stored_audits
from relaff_jax.sim.templates import stored_config


def _meta(cfg: ActionConfig) -> dict:
    return {"action": "lift", "config": {"action": "lift", "action_config": stored_config(cfg)}}


@pytest.mark.parametrize("cfg", [ActionConfig(programs="v1"), ActionConfig(programs="v2"), ActionConfig(),
                                 ActionConfig(programs="v1", lift_height=0.2, straight_pieces=8),
                                 ActionConfig(programs="v2", straight_pieces=3, squeeze_min=4.0)])
def test_the_replay_config_is_the_recorded_one(cfg):
    """``stored_config`` then ``audit.action_config`` gives the config back (v1's settings that
    v1 does not read are recorded by their absence, so they come back at their defaults)."""
    got = A.action_config(_meta(cfg))
    assert got.programs == cfg.programs and A.recorded_programs(_meta(cfg)) == cfg.programs
    assert stored_config(got) == stored_config(cfg)
    if cfg.programs == "v2":
        assert got == cfg


def test_a_sidecar_without_programs_is_v1():
    assert "programs" not in stored_config(ActionConfig(programs="v1"))
    assert A.recorded_programs({"config": {"action_config": {}}}) == "v1"
    assert A.recorded_programs({"config": {"action_config": {"programs": "v2"}}}) == "v2"


def _dataset(tmp_path, cfg: ActionConfig, audit: dict):
    d = tmp_path / cfg.programs
    d.mkdir(parents=True)
    side = {"format": FORMAT, "format_version": FORMAT_VERSION, "action": "lift", "n_samples": 4, "seed": 0,
            "batch": 8, "status": "complete", "counts": {"chunks": 0}, "engine": "native",
            "selection": {"sha256": "abc"}, "config": _meta(cfg)["config"]}
    (d / SIDECAR).write_text(json.dumps(side))
    (d / A.AUDIT_FILE).write_text(json.dumps(audit))
    return d


@pytest.mark.parametrize("programs", ["v1", "v2"])
def test_a_stored_audit_is_reused_only_when_it_replayed_the_datasets_programs(tmp_path, programs):
    """An audit.json without ``programs`` was replayed with v2 (before the version was read from
    the sidecar): kept for a v2 dataset, redone for a v1 one; one recording the dataset's
    version is kept, another version's redone."""
    head = {"version": A.AUDIT_VERSION, "sample": 64, "seed": 0, "selection_sha256": "abc"}
    cfg = ActionConfig(programs=programs)
    other = "v2" if programs == "v1" else "v1"
    dirs = {"none": _dataset(tmp_path / "a", cfg, head), "same": _dataset(tmp_path / "b", cfg, {**head, "programs": programs}),
            "other": _dataset(tmp_path / "c", cfg, {**head, "programs": other})}
    assert (A.stored_audit(dirs["none"], 64, 0) is None) == (programs == "v1")
    assert A.stored_audit(dirs["same"], 64, 0) is not None
    assert A.stored_audit(dirs["other"], 64, 0) is None
    found, missing = stored_audits(dirs)  # the report's reading: the same
    assert set(found) == ({"same"} if programs == "v1" else {"none", "same"}) and set(missing) == set(dirs) - set(found)
