"""The physics of executed programs in the keys of the programs' tests and force benchmark.

Takes an action, an ``ActionConfig`` and executed programs (the inputs and result of a native
replay, ``native.reference.replay_native``); gives ``physics``: the replay with ``native.probe.Probe``
as its ``observe`` hook (the audit's probe), its force, penetration and palm readings renamed
(``peak``, ``press``, ``depth``, ``palm``, ``weight``) beside the replay's label. The bounds
the programs keep: ``physics_bounds``; their reasoning: docs/arm.md, "Bounded forces".
"""
from __future__ import annotations

import numpy as np

from relaff_jax.sim.native.reference import replay_native
from relaff_jax.sim.native.probe import Probe
from relaff_jax.sim.planning import setup
from relaff_jax.sim.templates import ActionConfig


def physics(action: str, cfg: ActionConfig, pair: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
            result: dict) -> dict[str, np.ndarray]:
    """Replay B programs in C and read their contacts with ``Probe``.

    Returns (B,) arrays: ``peak`` (N) the largest summed normal force on either object in one
    step; ``press`` (N) the largest force on either object held over ``SUSTAIN_STEPS`` steps;
    ``depth`` (m) the deepest contact penetration involving an object, ``held_depth`` (m) the
    deepest held over ``SUSTAIN_STEPS`` steps; ``palm`` (N) the largest
    summed normal force between the palm (hand body) and the objects, ``palm_steps`` the steps
    with such a contact; ``weight`` (N) the heavier
    object's weight; and the replay's ``label``, ``settled`` and ``com_read``.
    """
    w = setup(cfg).world
    probe = Probe(len(pair), w.toy_body, w.obj_body, cfg.phys.timestep)
    out = replay_native(action, cfg, pair, qpos, qvel, result, observe=probe)
    got = probe.result(0)  # the forces do not depend on the measuring step
    return dict(peak=got["object_peak_n"], press=got["press_n"], depth=got["max_penetration_m"],
                held_depth=got["held_penetration_m"],
                palm=got["palm_force_n"], palm_steps=got["palm_steps"], weight=got["weight_n"],
                label=out["label"], settled=out["settled"], com_read=out["com_m"])
