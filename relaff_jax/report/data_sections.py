"""The report's blocks about the datasets: their statistics per action and the example scenes
(``write.py`` adds them with ``--data``; ``sections`` re-exports both)."""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from relaff_jax.constants import RELATIONS


def _rate(r) -> str:
    return "-" if r is None else f"{100 * r:.0f} %"


def dataset_blocks(infos: Mapping[str, Mapping[str, Any]], fig: str | None) -> list[tuple]:
    """Dataset statistics per action from ``relaff_jax.data.info`` dicts."""
    blocks: list[tuple] = [("h", 2, "Datasets"), (
        "p", "Per action: the balanced selection (half positive; negatives matched to the positives' distribution of the "
        "distance between the objects' centres of gravity) and every rollout simulated to find it. Positive rates by "
        "the settled spatial relation, over all rollouts (what the action does in each relation) and, with counts, "
        "over the selected samples. `unseen`: samples in which an object has fewer voxels than a PCA frame needs "
        "(occluded, out of view or too small); its nine PCA values are then zeros, a centroid at the robot base that no "
        "seen object has, and all 300 RHF values are zeros (docs/perception.md, 'Unseen objects').")]
    header = ["action", "samples", "rollouts", "rollout pos. rate"] + [f"rollouts {r}" for r in RELATIONS] \
        + [f"selected {r} (n)" for r in RELATIONS] + ["borrowed", "unseen"]
    rows = []
    for action, d in infos.items():
        sel = [f"{_rate(d['positive_rate_by_relation'][r])} ({d['count_by_relation'][r]['n']})" for r in RELATIONS]
        feats = d.get("features") or {}
        rows.append([action, d["n"], d["rollouts"], _rate(d["rollouts_positive_rate"])]
                    + [_rate(d["rollouts_positive_rate_by_relation"][r]) for r in RELATIONS] + sel
                    + [d.get("borrowed"), feats.get("unseen_samples", "-")])
    blocks.append(("table", header, rows))
    if fig:
        blocks.append(("img", fig, "Positive rate of every rollout by spatial relation, per action"))
    return blocks


def example_blocks(shown: Sequence[tuple[str, str, str]]) -> list[tuple]:
    """The example scenes ``[(action, relative path, caption)]`` of ``examples.example_scenes``."""
    if not shown:
        return []
    blocks: list[tuple] = [("h", 2, "Example scenes"),
                           ("p", "What the robot saw (`perception.from_sim.show_scene`): the simulated Kinect depth image, its "
                                 "colour segmentation into the toy and the other object, and the two objects' voxel clouds "
                                 "with their PCA frames.")]
    return blocks + [("img", path, cap) for _, path, cap in shown]
