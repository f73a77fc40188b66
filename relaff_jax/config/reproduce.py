"""What ``relaff reproduce`` covers besides the stages' own settings (the tree's ``reproduce`` node)."""
from __future__ import annotations

import dataclasses

from relaff_jax.config.constraints import Check, Options, Rule, Seq, count
from relaff_jax.config.node import Node
from relaff_jax.constants import ACTIONS, SPACES
from relaff_jax.sim.actions.registry import names


@dataclasses.dataclass(frozen=True)
class ReproduceConfig(Node):
    """actions: the actions studied (the paper's nine, and registered user actions after them; at
      least two, in the run's order ``sim.actions.names()``).
    spaces: state spaces of the experiment.
    examples_per_action: example scenes drawn per action in the report.
    """

    actions: tuple[str, ...] = ACTIONS
    spaces: tuple[str, ...] = SPACES
    examples_per_action: int = 2

    _path = "reproduce"
    _constraints = {
        "actions": Seq(Check(lambda a: a in _names(), "an action: one of the nine, or a user action registered by "
                             "--plugins FILE.py"), min_len=2, distinct=True),
        "spaces": Seq(Options(SPACES), distinct=True),
        "examples_per_action": count(0, 10_000),
        ("actions",): Rule(lambda c: tuple(c.actions) == tuple(a for a in _names() if a in c.actions),
                           lambda c: f"must be in the run's order {list(_names())} (the nine, then the user's), "
                                     f"got {list(c.actions)}"),
    }


def _names() -> tuple[str, ...]:
    """The run's actions: ``ACTIONS``, then the registered user actions (the registry loads no JAX)."""
    return tuple(names())
