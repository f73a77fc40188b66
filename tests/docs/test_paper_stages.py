"""``benchmarks/paper_stages.py``'s projection of the paper preset, on a hand-worked case."""
from __future__ import annotations

import sys

import pytest

from helpers import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

import paper_stages as P  # noqa: E402


def test_projection_hand_worked():
    """The projection on two timed actions, from the script's record of the paper run
    (``PAPER_RUN_*``, which a test cannot know independently, so it is read, not copied)."""
    rollout = [dict(action="lift", per_s=100.0, first_s=30.0, batch=1000, n=2000),
               dict(action="take", per_s=200.0, first_s=5.0, batch=1000, n=2000)]
    got = P.project(rollout, {"rates": {"new": 100.0}})
    runs = P.PAPER_RUN_ROLLOUTS
    # lift at 100 /s, take at 200 /s, the other seven at the mean 150 /s, plus one compile:
    # the first call's 30 s less one batch at the rate (10 s)
    others = sum(n for a, n in runs.items() if a not in ("lift", "take"))
    assert len(runs) == 9 and others == sum(runs.values()) - runs["lift"] - runs["take"]
    data = runs["lift"] / 100.0 + runs["take"] / 200.0 + others / 150.0 + 20.0
    features = P.PAPER_SCENES / 100.0
    experiment = P.PAPER_RUN_S["experiment"] * P.EXPERIMENT_RATIO
    report = P.PAPER_RUN_S["report"] / P.REPORT_RATIO
    assert got["projected"]["data"] == pytest.approx(data)
    assert got["projected"]["features"] == pytest.approx(features)
    assert got["projected"]["experiment"] == pytest.approx(experiment)
    assert got["projected"]["report"] == pytest.approx(report)
    assert got["projected"]["total"] == pytest.approx(data + features + experiment + report)
    assert got["measured"] == dict(P.PAPER_RUN_S, total=sum(P.PAPER_RUN_S.values()))
    # a faster rollout rate projects a shorter data stage and leaves the other stages alone
    fast = P.project([dict(r, per_s=2 * r["per_s"]) for r in rollout], {"rates": {"new": 100.0}})
    assert fast["projected"]["data"] < got["projected"]["data"]
    assert {k: fast["projected"][k] for k in ("features", "experiment", "report")} == \
        {k: got["projected"][k] for k in ("features", "experiment", "report")}
