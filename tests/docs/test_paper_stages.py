"""``benchmarks/paper_stages.py``'s projection of the paper preset, on a hand-worked case."""
from __future__ import annotations

import sys

import pytest

from helpers import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

import paper_stages as P  # noqa: E402


def test_projection_hand_worked():
    rollout = [dict(action="lift", per_s=100.0, first_s=30.0, batch=1000, n=2000),
               dict(action="take", per_s=200.0, first_s=5.0, batch=1000, n=2000)]
    got = P.project(rollout, {"rates": {"new": 100.0}})
    # lift 20,480 / 100 + take 181,248 / 200 + the other seven's 246,784 at the mean 150 /s,
    # plus one compile: the first call's 30 s less one batch at the rate (10 s)
    others = 31_744 + 20_480 + 34_816 + 14_336 + 46_080 + 54_272 + 45_056
    assert others == 246_784
    data = 204.8 + 906.24 + others / 150 + 20.0
    assert got["projected"]["data"] == pytest.approx(data)
    assert got["projected"]["features"] == pytest.approx(900.0)  # 90,000 scenes at 100 /s
    assert got["projected"]["experiment"] == pytest.approx(1_624.5)  # the paper run's 2,850 s x 0.57
    assert got["projected"]["report"] == pytest.approx(1_942 / 2.51)  # the stage's reference / new
    assert got["projected"]["total"] == pytest.approx(data + 900 + 1_624.5 + 1_942 / 2.51)
    assert got["measured"] == {"data": 7_014, "features": 1_457, "experiment": 2_850, "report": 1_942,
                               "total": 13_263}
    assert sum(P.PAPER_RUN_ROLLOUTS.values()) == 448_512  # docs/reproduce.md, the paper run
