"""What ``relaff reproduce`` covers besides the stages' own settings (the tree's ``reproduce`` node)."""
from __future__ import annotations

import dataclasses

from relaff_jax.config.constraints import Options, Rule, Seq, count
from relaff_jax.config.node import Node
from relaff_jax.constants import ACTIONS, SPACES


@dataclasses.dataclass(frozen=True)
class ReproduceConfig(Node):
    """actions: the actions studied (the paper's nine; at least two, in ``ACTIONS`` order).
    spaces: state spaces of the experiment.
    examples_per_action: example scenes drawn per action in the report.
    """

    actions: tuple[str, ...] = ACTIONS
    spaces: tuple[str, ...] = SPACES
    examples_per_action: int = 2

    _path = "reproduce"
    _constraints = {
        "actions": Seq(Options(ACTIONS), min_len=2, distinct=True),
        "spaces": Seq(Options(SPACES), distinct=True),
        "examples_per_action": count(0, 10_000),
        ("actions",): Rule(lambda c: tuple(c.actions) == tuple(a for a in ACTIONS if a in c.actions),
                           lambda c: f"must be in the canonical order {ACTIONS}, got {list(c.actions)}"),
    }
