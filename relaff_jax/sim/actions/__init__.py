"""Actions as declared specs, found through one registry: the public API of action plugins.

An action is an ``ActionSpec`` (name, pairing, motor-program segments, target rule, goal rule,
which after state the goal reads, grasp kind); the nine of the paper are built-ins declared the
same way (``builtin.py``); a user's are registered with ``register_action`` in a Python file
(``--plugins FILE.py``) or through the entry point group ``relaff_jax.actions``. The compiled
programs are built from ``registry()`` (``tables.tables``, ``planning.make_plan_fn``,
``simulate.make_simulate_fn``) and index it with the traced action id. docs/extending.md, "Actions".

The spec and registry names load without JAX; the rule helpers on first use.
"""
from __future__ import annotations

from relaff_jax.lazy import lazy_attributes

from .registry import ENTRY_POINTS, names, record, register_action, registry, spec, spec_hash
from .spec import GRASP_KINDS, READINGS, ActionSpec

_LAZY = {
    "Settled": "rules", "Reading": "rules", "Program": "rules", "IKTarget": "rules", "base_grasp": "rules",
    "carry": "rules", "lift": "rules", "transit_z": "rules", "top_down": "_api", "stack_targets": "_api",
    "unit_xy": "_api", "perp": "_api", "check_actions": "check",
}

__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "ActionSpec", "ENTRY_POINTS", "GRASP_KINDS", "IKTarget", "Program", "READINGS", "Reading", "Settled",
    "base_grasp", "carry", "check_actions", "lift", "names", "perp", "record", "register_action", "registry",
    "spec", "spec_hash", "stack_targets", "top_down", "transit_z", "unit_xy",
]
