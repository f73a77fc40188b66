"""Actions as declared specs, found through one registry: the public API of action plugins.

An action is an ``ActionSpec`` (name, pairing, motor-program segments, target rule, goal rule,
which after state the goal reads, grasp kind); the nine of the paper are built-ins declared the
same way (``builtin.py``); a user's are registered with ``register_action`` in a Python file
(``--plugins FILE.py``) or through the entry point group ``relaff_jax.actions``. The compiled
programs are built from ``registry()`` (``tables.tables``, ``planning.make_plan_fn``,
``simulate.make_simulate_fn``) and index it with the traced action id. docs/extending.md, "Actions".

Only the spec and the registry are imported here (no JAX: the command line's checks read them);
a plugin's rule helpers (``Settled``, ``Reading``, ``carry``, ``lift``, ``top_down``, ...) are in
``rules.py`` and the compiled check of a spec is ``check.check_actions`` (both import JAX).
"""
from __future__ import annotations

from .registry import ENTRY_POINTS, names, record, register_action, registry, spec, spec_hash
from .spec import GRASP_KINDS, READINGS, ActionSpec

__all__ = ["ActionSpec", "ENTRY_POINTS", "GRASP_KINDS", "READINGS", "names", "record", "register_action", "registry",
           "spec", "spec_hash"]
