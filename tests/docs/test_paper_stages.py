"""``benchmarks/paper_stages.py``'s projection of the paper preset, on a hand-worked case."""
from __future__ import annotations

import sys

import pytest

from helpers import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

import paper_stages as P  # noqa: E402


def test_projection_hand_worked():
    """The projection on two timed actions, from the script's record of the v4 paper run
    (``PAPER_RUN_*``, which a test cannot know independently, so it is read, not copied)."""
    rollout = [dict(action="lift", per_s=100.0, first_s=30.0, batch=1000, n=2000),
               dict(action="take", per_s=200.0, first_s=5.0, batch=1000, n=2000)]
    got = P.project(rollout)
    runs = P.PAPER_RUN_ROLLOUTS
    # lift at 100 /s, take at 200 /s, the other seven at the mean 150 /s, plus one compile:
    # the first call's 30 s less one batch at the rate (10 s)
    others = sum(n for a, n in runs.items() if a not in ("lift", "take"))
    assert len(runs) == 9 and others == sum(runs.values()) - runs["lift"] - runs["take"]
    assert sum(runs.values()) == 372_736  # the v4 datasets' rollouts (docs/results.md)
    data = runs["lift"] / 100.0 + runs["take"] / 200.0 + others / 150.0 + 20.0
    assert got["projected"]["data"] == pytest.approx(data)
    later = P.PAPER_RUN_S["features"] + P.PAPER_RUN_S["experiment"] + P.PAPER_RUN_S["report"]
    assert {k: got["projected"][k] for k in ("features", "experiment", "report")} == P.PAPER_RUN_S
    assert got["projected"]["total"] == pytest.approx(data + later)
    assert got["measured"] == dict(P.PAPER_RUN_S, total=later)  # no data stage measured in one stretch
    # a faster rollout rate projects a shorter data stage and leaves the other stages alone
    fast = P.project([dict(r, per_s=2 * r["per_s"]) for r in rollout])
    assert fast["projected"]["data"] < got["projected"]["data"]
    assert {k: fast["projected"][k] for k in ("features", "experiment", "report")} == \
        {k: got["projected"][k] for k in ("features", "experiment", "report")}
