"""The physics of executed programs, read from MuJoCo C: contact forces, depths, palm presses.

Takes an action, an ``ActionConfig`` and executed programs (the inputs and result of a native
replay, ``native.replay_native``); gives per scene the peak contact force on each object, the
peak force it bears for ``SUSTAIN`` consecutive control steps (a press, not an impact), the
deepest penetration of any contact with an object, and the peak force of the palm on an
object (``physics``). Forces are ``mj_contactForce``'s normal components, each object's
contacts summed per step (with the table, the other object, the pads and the palm), in N.
The bounds the programs keep (v2) and their reasoning: docs/arm.md, "Bounded forces".
"""
from __future__ import annotations

import mujoco
import numpy as np

from .native import replay_native
from .planning import setup
from .simulate import welds
from .templates import ActionConfig

SUSTAIN = 25  # control steps (0.1 s at 4 ms): a force held this long is a press, not an impact


def physics(action: str, cfg: ActionConfig, pair: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
            result: dict) -> dict[str, np.ndarray]:
    """Replay B programs in C and measure their contacts (a ``replay_native`` with a probe).

    Returns (B,) arrays: ``peak`` (N) the largest summed normal force on either object in one
    step; ``press`` (N) the largest force on either object held over ``SUSTAIN`` steps (the
    minimum over a window, maximised over windows); ``depth`` (m) the deepest contact
    penetration involving an object; ``palm`` (N) the largest normal force between the palm
    and an object; ``weight`` (N) the heavier object's weight; and the replay's ``label`` and
    ``settled``.
    """
    st = setup(cfg)
    wl = welds(st.world)
    obj = np.zeros(st.world.mj_model.ngeom, np.int8)
    obj[wl.toy_geoms], obj[wl.obj_geoms] = 1, 2
    palm = st.arm.palm_geom
    n = len(pair)
    per_step = [[] for _ in range(n)]
    depth, palm_f = np.zeros(n), np.zeros(n)
    f6 = np.zeros(6)

    def probe(b, t, m, d):
        tot = np.zeros(3)
        geom = d.contact.geom[:d.ncon]
        kind = obj[geom]  # (ncon, 2)
        for i in np.flatnonzero(kind.any(axis=1)):
            mujoco.mj_contactForce(m, d, int(i), f6)
            f = abs(f6[0])
            tot[kind[i, 0]] += f
            tot[kind[i, 1]] += f
            depth[b] = max(depth[b], -float(d.contact.dist[i]))
            if palm in geom[i]:
                palm_f[b] = max(palm_f[b], f)
        per_step[b].append(max(tot[1], tot[2]))

    out = replay_native(action, cfg, pair, qpos, qvel, result, observe=probe)
    peak = np.array([max(s) if s else 0.0 for s in per_step])
    press = np.zeros(n)
    for b, s in enumerate(per_step):
        s = np.asarray(s)
        if len(s) >= SUSTAIN:
            win = np.lib.stride_tricks.sliding_window_view(s, SUSTAIN).min(axis=-1)
            press[b] = win.max()
    masses = [max(st.world.mj_models[int(p)].body_mass[st.world.toy_body],
                  st.world.mj_models[int(p)].body_mass[st.world.obj_body]) for p in pair]
    return dict(peak=peak, press=press, depth=depth, palm=palm_f, weight=9.81 * np.asarray(masses),
                label=out["label"], settled=out["settled"], com_read=out["com_m"])
