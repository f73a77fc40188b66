"""The audit's probe read from MuJoCo's contact arrays: ``probe.Probe``'s readings, bit for bit, faster.

Takes the same calls as ``probe.Probe`` (``probe(b, t, m, d)`` after each ``mj_step`` of
rollout b, ``result(measure)``); gives the same (B,) arrays, every value equal to ``Probe``'s
(``tests/sim/test_probe_arrays.py``). What it does differently, and why the bits stay the same:

- per step it copies only the rows of ``d.contact`` with an object on one side (bodies, the
  pyramid's forces ``efc_force[efc_address:+2(dim-1)]``, 0 past the contact's width) and the
  deepest of them (``argmin`` of ``dist``, the first on ties, as ``Probe``); the summing is done
  once per rollout in ``result``;
- a contact's normal force is ``mj_contactForce``'s for the pyramidal cone
  (``mju_decodePyramid``: 0, then each pyramid force added in order; a frictionless contact's one
  value; 0 without a constraint row), summed column by column in that order;
- sums per body pair, per object and over the palm's pairs use ``np.add.at``, which adds in
  contact order from 0 as ``Probe``'s loop does; the peak is the first (step, pair) in ``Probe``'s
  dict order with the largest ratio, which is the one its strict ``>`` update keeps;
- a palm contact's normal is the z of ``d.contact.frame``'s first row, the value ``Probe`` reads
  from ``d.contact[i].frame``; from above or from the side by the same ``probe.from_above``;
- ``mj_objectVelocity`` is called every step (the C function ``Probe`` calls) but the norm and
  the held test (``probe.held_bodies``'s rule on the step's ``eq_active``) only at the
  steps ``result`` reads.
"""
from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from relaff_jax.sim.physics_bounds import SUSTAIN_STEPS
from .probe import HAND_BODY, body_names, from_above, held_peak, welded_to


class _Model:
    """What the probe needs of one ``MjModel``, computed once."""

    def __init__(self, m: mujoco.MjModel, objects: tuple[int, int]):
        self.m = m
        self.names = body_names(m)
        self.hand = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, HAND_BODY)
        self.weight = np.asarray(m.body_mass) * float(np.linalg.norm(m.opt.gravity))
        self.geom_body = np.asarray(m.geom_bodyid)
        self.is_obj = np.zeros(m.nbody, bool)
        self.is_obj[list(objects)] = True
        self.pyramidal = m.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
        self.width = 10  # 2 (condim 6 - 1): the widest pyramid
        self.cols = np.arange(self.width)


class _Rollout:
    """One rollout's raw per-step copies (the contact arrays and constraint forces)."""

    def __init__(self):
        self.model: _Model | None = None
        self.geom: list[np.ndarray] = []  # per step (ncon, 2)
        self.dist: list[np.ndarray] = []  # per step (ncon,)
        self.nz: list[np.ndarray] = []  # per step (ncon,) the contact normal's z
        self.adr: list[np.ndarray] = []  # per step (ncon,) efc_address
        self.dim: list[np.ndarray] = []  # per step (ncon,)
        self.efc: list[np.ndarray] = []  # per step (nefc,) efc_force
        self.vel: list[np.ndarray] = []  # per step (2, 6) mj_objectVelocity of (toy, other)
        self.eq_active: list[np.ndarray] = []


class ArrayProbe:
    """``probe.Probe`` from contact arrays: ``ArrayProbe(n, toy_body, obj_body,
    timestep)``, ``probe(b, t, m, d)`` after step t of rollout b, ``result(measure)``: the
    same dict of (B,) arrays as ``Probe.result``."""

    def __init__(self, n: int, toy_body: int, obj_body: int, timestep: float):
        self.objects = (int(toy_body), int(obj_body))
        self.timestep = float(timestep)
        self.runs = [_Rollout() for _ in range(n)]
        self._models: dict[int, _Model] = {}

    def __call__(self, b: int, t: int, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        mm = self._models.get(id(m))
        if mm is None:
            mm = self._models[id(m)] = _Model(m, self.objects)
        run = self.runs[b]
        run.model = mm
        assert len(run.vel) == t, "observe every step of a rollout in order"
        con = d.contact  # copies of this step's arrays (views of d, sized ncon); the work is done in result
        run.geom.append(np.array(con.geom))
        run.dist.append(np.array(con.dist))
        run.nz.append(np.array(con.frame[:, 2]))
        run.adr.append(np.array(con.efc_address))
        run.dim.append(np.array(con.dim))
        run.efc.append(np.array(d.efc_force))
        vel = np.empty((2, 6))
        for j, body in enumerate(self.objects):
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body, vel[j], 0)
        run.vel.append(vel)
        run.eq_active.append(np.array(d.eq_active))

    @staticmethod
    def _pyramid(mm: _Model, efc: np.ndarray, adr: np.ndarray, dim: np.ndarray) -> np.ndarray:
        """(k, width) the forces ``mj_contactForce`` sums into each contact's normal force
        (``efc`` the constraint forces, ``adr`` each contact's first row or -1), 0 elsewhere."""
        if mm.pyramidal:
            n_used = np.where(dim == 1, 1, 2 * (dim - 1))
        else:  # elliptic: the normal force is the first row's
            n_used = np.ones_like(dim)
        use = (mm.cols[None, :] < n_used[:, None]) & (adr[:, None] >= 0)
        idx = np.where(use, adr[:, None] + mm.cols[None, :], 0)
        return np.where(use, efc[idx], 0.0)

    def result(self, measure: int | np.ndarray) -> dict[str, Any]:
        """``measure``: the step the goal is read at, one for all rollouts or (B,) per rollout."""
        ms = np.broadcast_to(np.asarray(measure, int), (len(self.runs),))
        rows = [self._one(run, int(mstep)) for run, mstep in zip(self.runs, ms)]
        out = {k: np.asarray([r[k] for r in rows]) for k in rows[0]} if rows else {}
        for k in ("peak_pair", "penetration_pair"):
            out[k] = np.asarray([r[k] for r in rows], str)
        return out

    def _one(self, run: _Rollout, measure: int) -> dict[str, Any]:
        mm, steps = run.model, len(run.vel)
        if mm is None:  # never observed
            return self._empty()
        hand, names, weight = mm.hand, mm.names, mm.weight
        o0, o1 = self.objects
        ncon = np.asarray([len(x) for x in run.dist])
        step = np.repeat(np.arange(steps), ncon)  # (N,) the step of each contact
        efc_start = np.cumsum([0] + [len(x) for x in run.efc])[:-1]
        efc = np.concatenate(run.efc) if run.efc else np.zeros(0)
        adr = np.concatenate(run.adr).astype(np.int64)
        adr = np.where(adr >= 0, adr + efc_start[step], -1)  # into the concatenated forces
        bodies = mm.geom_body[np.concatenate(run.geom).reshape(-1, 2)]
        obj = mm.is_obj[bodies]
        rows = obj[:, 0] | obj[:, 1]  # the contacts with an object on one side, in step and contact order
        step, bodies, dist = step[rows], bodies[rows], np.concatenate(run.dist)[rows]
        pyr = self._pyramid(mm, efc, adr[rows], np.concatenate(run.dim)[rows])
        # per step the deepest of them (the first on ties, as argmin): sorted by step, dist, order
        first_deep = np.lexsort((np.arange(len(dist)), dist, step))
        first_deep = first_deep[np.r_[True, step[first_deep][1:] != step[first_deep][:-1]]] if len(dist) else first_deep
        depth = np.zeros(steps)
        where = np.zeros((steps, 2), np.int64)
        depth[step[first_deep]] = [float(max(0.0, -x)) for x in dist[first_deep]]
        where[step[first_deep]] = np.sort(bodies[first_deep], axis=1)
        force = np.zeros(len(bodies))
        for c in range(pyr.shape[1]):  # mju_decodePyramid's order: 0, then each force in turn
            force += pyr[:, c]
        lo, hi = bodies.min(axis=1), bodies.max(axis=1)
        code = (step * mm.m.nbody + lo) * mm.m.nbody + hi  # one group per (step, body pair)
        _, first, inv = np.unique(code, return_index=True, return_inverse=True)
        pair_f = np.zeros(len(first))
        np.add.at(pair_f, inv.reshape(-1), force)  # in contact order, from 0
        order = np.argsort(first, kind="stable")  # Probe's dict order: step, then first contact
        pair_f, first = pair_f[order], first[order]
        plo, phi, pstep = lo[first], hi[first], step[first]
        w = np.maximum(np.where(mm.is_obj[plo], weight[plo], -np.inf), np.where(mm.is_obj[phi], weight[phi], -np.inf))
        ratio = pair_f / w
        peak_n, peak_w, peak_pair, peak_step = 0.0, 0.0, "", -1
        if len(ratio) and ratio.max() > 0.0:
            i = int(np.argmax(ratio))
            peak_n, peak_w, peak_step = float(pair_f[i]), float(ratio[i]), int(pstep[i])
            peak_pair = f"{names[plo[i]]}|{names[phi[i]]}"
        has_hand = (plo == hand) | (phi == hand)
        palm_step = np.zeros(steps)
        np.add.at(palm_step, pstep[has_hand], pair_f[has_hand])
        hand_steps = np.zeros(steps, bool)
        hand_steps[step[(bodies[:, 0] == hand) | (bodies[:, 1] == hand)]] = True
        palm_force = float(max(0.0, palm_step[hand_steps].max())) if hand_steps.any() else 0.0
        on = np.zeros((2, steps))
        for j, o in enumerate((o0, o1)):
            has = (bodies[:, 0] == o) | (bodies[:, 1] == o)
            np.add.at(on[j], step[has], force[has])
        load = np.maximum(on[0], on[1])
        pen, pen_pair = 0.0, ""
        if steps and depth.max() > 0.0:
            i = int(np.argmax(depth))
            pen, pen_pair = float(depth[i]), f"{names[where[i, 0]]}|{names[where[i, 1]]}"
        weight_n = max(weight[x] for x in self.objects)
        speed = lambda s: tuple(float(np.linalg.norm(run.vel[s][j][3:])) for j in range(2))
        if measure < steps:
            at, held = speed(measure), self._held(mm, run.eq_active[measure])
        else:
            at, held = (np.nan, np.nan), (False, False)
        press = held_peak(load, SUSTAIN_STEPS)
        n_palm = int(hand_steps.sum())
        on_hand = (bodies[:, 0] == hand) | (bodies[:, 1] == hand)
        top = from_above(np.concatenate(run.nz)[rows])
        split = [self._palm_split(step[sel], force[sel], steps) for sel in (on_hand & top, on_hand & ~top)]
        return dict(palm_contact=n_palm > 0, palm_steps=n_palm, palm_seconds=n_palm * self.timestep,
                    palm_force_n=palm_force, palm_top_steps=split[0][0], palm_top_force_n=split[0][1],
                    palm_side_steps=split[1][0], palm_side_force_n=split[1][1], peak_force_n=peak_n, peak_force_weights=peak_w,
                    peak_pair=peak_pair, peak_step=peak_step, max_penetration_m=pen, penetration_pair=pen_pair,
                    held_penetration_m=held_peak(depth, SUSTAIN_STEPS),
                    speed_toy=at[0], speed_other=at[1], held_toy=held[0], held_other=held[1],
                    speed_end=max(speed(steps - 1)) if steps else np.nan,
                    object_peak_n=float(load.max()) if steps else 0.0,
                    press_n=press, weight_n=weight_n, press_weights=press / weight_n if weight_n > 0 else 0.0)

    @staticmethod
    def _palm_split(step: np.ndarray, force: np.ndarray, steps: int) -> tuple[int, float]:
        """(steps with one of these palm contacts, the largest per-step sum of their forces):
        summed in contact order from 0, as ``step_contacts``."""
        per_step = np.zeros(steps)
        np.add.at(per_step, step, force)
        has = np.zeros(steps, bool)
        has[step] = True
        return int(has.sum()), float(max(0.0, per_step[has].max())) if has.any() else 0.0

    def _held(self, mm: _Model, eq_active: np.ndarray) -> tuple[bool, bool]:
        """``probe.held_bodies``'s rule on a recorded ``eq_active``."""
        out = welded_to(mm.m, eq_active, mm.hand)
        return self.objects[0] in out, self.objects[1] in out

    def _empty(self) -> dict[str, Any]:
        return dict(palm_contact=False, palm_steps=0, palm_seconds=0.0, palm_force_n=0.0, palm_top_steps=0,
                    palm_top_force_n=0.0, palm_side_steps=0, palm_side_force_n=0.0, peak_force_n=0.0,
                    peak_force_weights=0.0, peak_pair="", peak_step=-1, max_penetration_m=0.0, penetration_pair="",
                    held_penetration_m=0.0, speed_toy=np.nan, speed_other=np.nan, held_toy=False,
                    held_other=False, speed_end=np.nan, object_peak_n=0.0, press_n=0.0, weight_n=0.0,
                    press_weights=0.0)
