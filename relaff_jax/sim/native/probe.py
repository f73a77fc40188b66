"""What a rollout's physics does, step by step, read from MuJoCo C contacts (the audit's probe).

Takes a pair's arm-world ``MjModel`` and its ``MjData`` after each ``mj_step`` of a motor
program (``native.reference.replay_native``'s ``observe`` hook); gives ``Probe``, which records per
rollout:

- palm contacts: contacts between a geom of the hand body (``arm_hand``: the palm block, not
  the finger pads) and the toy or the other object, the steps they last and the largest sum of
  their normal forces; and the same split by the contact's normal (``from_above``): from above
  (within ``physics_bounds.PALM_ABOVE_DEG`` of vertical: the palm on an object's top, a press)
  and from the side (the palm pushing an object sideways);
- contact forces: at every step, the normal forces (``mj_contactForce``) of all contacts
  between one body pair that involves an object summed per pair, divided by the weight of the
  heaviest object of the pair (a box resting on the table reads 1); the peak over steps and
  pairs, in newtons and in weights, and which pair;
- the press: at every step, the normal forces of all contacts on each object summed (with
  the table, the other object, the pads and the palm; a toy-object contact counts for both),
  the larger of the two; its peak over steps, and its peak held over ``SUSTAIN_STEPS``
  consecutive steps (the minimum over a window, maximised over windows: a press, not an
  impact), in newtons and in weights of the heavier object (the bound of
  ``physics_bounds.PRESS_WEIGHTS``);
- penetration: the deepest contact (``-dist``) that involves an object, in one step and held
  over ``SUSTAIN_STEPS`` steps (a toy dropping onto the table sinks into MuJoCo's soft contact
  for the contact's time constant, ~20 ms: an impact; a press holds its depth);
- the objects' speeds (linear, at the centre of mass, ``mj_objectVelocity``) at the step whose
  positions the goal reads (``ProgramInputs.measure``), and whether each is then welded to the
  hand (held: its motion is the arm's).

Everything is float64 numpy; ``step_contacts`` is the per-step reading (a pure function of
the model and data), ``Probe`` accumulates it over the steps of B rollouts. ``Probe`` reads
each contact through ``d.contact[i]`` and ``mj_contactForce``: the reference of
``probe_arrays.ArrayProbe``, which the audit uses (the same readings from the contact arrays).
"""
from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from relaff_jax.sim.physics_bounds import PALM_ABOVE_COS, SUSTAIN_STEPS

HAND_BODY = "arm_hand"  # the palm block's body; the pads are on the finger bodies


def body_names(m: mujoco.MjModel) -> list[str]:
    return [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i) or f"body{i}" for i in range(m.nbody)]


def from_above(normal_z: float | np.ndarray) -> bool | np.ndarray:
    """Is a contact whose normal has z component ``normal_z`` from above (within
    ``PALM_ABOVE_DEG`` of vertical)? ``|n_z|``: the normal's sign (which geom is first) does not matter."""
    return np.abs(normal_z) >= PALM_ABOVE_COS


def step_contacts(m: mujoco.MjModel, d: mujoco.MjData, objects: tuple[int, int], hand: int
                  ) -> tuple[dict[tuple[int, int], float], np.ndarray, float, tuple[int, int], np.ndarray]:
    """One step's contacts that involve an object.

    objects: body ids of the toy and the other object; hand: the hand body's id.
    Returns ``forces`` {(body a, body b) sorted: summed normal force (N)} over contacts with an
    object on one side, ``on`` (2,) the summed normal force on the toy and on the other object
    (N, in contact order), the deepest penetration (m, >= 0) among them and its body pair, and
    ``palm`` (2, 2): per row, from above and from the side (``from_above``), the number of
    hand-object contacts and their summed normal force (N, in contact order).
    """
    n = d.ncon
    forces: dict[tuple[int, int], float] = {}
    on = np.zeros(2)
    palm = np.zeros((2, 2))
    if n == 0:
        return forces, on, 0.0, (0, 0), palm
    bodies = np.asarray(m.geom_bodyid)[np.asarray(d.contact.geom[:n])]  # (n, 2)
    dist = np.asarray(d.contact.dist[:n])
    o0, o1 = objects
    rows = np.flatnonzero((bodies == o0).any(axis=1) | (bodies == o1).any(axis=1))
    if not len(rows):
        return forces, on, 0.0, (0, 0), palm
    k = rows[int(np.argmin(dist[rows]))]
    deepest, where = float(max(0.0, -dist[k])), tuple(sorted(bodies[k].tolist()))
    f6 = np.zeros(6)
    for i in rows.tolist():
        mujoco.mj_contactForce(m, d, i, f6)
        a, b = bodies[i]
        key = (int(a), int(b)) if a <= b else (int(b), int(a))
        forces[key] = forces.get(key, 0.0) + float(f6[0])
        for j, o in enumerate(objects):
            on[j] += float(f6[0]) if o in (a, b) else 0.0
        if hand == a or hand == b:
            side = 0 if from_above(d.contact[i].frame[2]) else 1  # frame[:3]: the contact normal
            palm[side, 0] += 1
            palm[side, 1] += float(f6[0])
    return forces, on, deepest, where, palm


def held_bodies(m: mujoco.MjModel, d: mujoco.MjData, hand: int) -> set[int]:
    """Bodies welded to the hand by an active equality constraint (the grasp lock, the rake)."""
    return welded_to(m, np.asarray(d.eq_active), hand)


def welded_to(m: mujoco.MjModel, eq_active: np.ndarray, hand: int) -> set[int]:
    """``held_bodies`` for the equality constraints' activity ``eq_active`` (neq,)."""
    rows = np.flatnonzero((np.asarray(m.eq_type) == mujoco.mjtEq.mjEQ_WELD) & (eq_active != 0))
    out = set()
    for r in rows:
        a, b = int(m.eq_obj1id[r]), int(m.eq_obj2id[r])
        if hand in (a, b):
            out.add(b if a == hand else a)
    return out


class Probe:
    """Accumulates ``step_contacts`` over the steps of B rollouts (an ``observe`` hook).

    ``Probe(n, toy_body, obj_body, timestep)``; call ``probe(b, t, m, d)`` after step t of
    rollout b; ``result(measure)`` gives (B,) arrays: ``palm_contact`` bool, ``palm_steps``,
    ``palm_seconds``,
    ``palm_force_n`` (largest summed hand-object normal force), ``palm_top_steps``,
    ``palm_top_force_n``, ``palm_side_steps``, ``palm_side_force_n`` (the same for the
    contacts from above and from the side: a step with both counts for both), ``peak_force_n``,
    ``peak_force_weights`` (peak over steps and pairs of the summed force / the pair's
    heaviest object's weight), ``peak_pair`` (str "a|b" body names), ``peak_step``,
    ``max_penetration_m``, ``penetration_pair``, ``held_penetration_m`` (the deepest held over
    ``SUSTAIN_STEPS`` steps; 0 for a shorter rollout), ``speed_toy``/``speed_other`` (m/s at the
    measuring step ``measure``; NaN if it was not reached), ``held_toy``/``held_other`` (welded
    to the hand at that step: a held object moves with the arm, its speed is the arm's),
    ``speed_end`` (the faster object's speed at the last step), ``object_peak_n`` (the largest
    summed force on one object in one step), ``press_n`` (the largest held over
    ``SUSTAIN_STEPS`` steps; 0 for a shorter rollout), ``weight_n`` (the heavier object's
    weight) and ``press_weights`` (``press_n / weight_n``).
    """

    def __init__(self, n: int, toy_body: int, obj_body: int, timestep: float):
        self.objects = (int(toy_body), int(obj_body))
        self.timestep = float(timestep)
        self.palm_steps = np.zeros(n, np.int64)
        self.palm_force = np.zeros(n)
        self.palm_split_steps = np.zeros((n, 2), np.int64)  # (top, side)
        self.palm_split_force = np.zeros((n, 2))
        self.peak_n = np.zeros(n)
        self.peak_w = np.zeros(n)
        self.peak_pair = np.full(n, "", object)
        self.peak_step = np.full(n, -1, np.int64)
        self.pen = np.zeros(n)
        self.pen_pair = np.full(n, "", object)
        self.speeds: list[list[tuple[float, float]]] = [[] for _ in range(n)]  # per step (toy, other)
        self.held: list[list[tuple[bool, bool]]] = [[] for _ in range(n)]  # welded to the hand, per step
        self.load: list[list[float]] = [[] for _ in range(n)]  # per step: the larger object's summed force
        self.depth: list[list[float]] = [[] for _ in range(n)]  # per step: the deepest contact with an object
        self.weight_n = np.zeros(n)
        self._names: dict[int, list[str]] = {}
        self._hand: dict[int, int] = {}
        self._weight: dict[int, np.ndarray] = {}
        self._vel = np.zeros(6)

    def __call__(self, b: int, t: int, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        key = id(m)
        if key not in self._names:
            self._names[key] = body_names(m)
            self._hand[key] = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, HAND_BODY)
            self._weight[key] = np.asarray(m.body_mass) * float(np.linalg.norm(m.opt.gravity))
        hand, names, weight = self._hand[key], self._names[key], self._weight[key]
        forces, on, deepest, where, split = step_contacts(m, d, self.objects, hand)
        self.load[b].append(float(on.max()))
        self.depth[b].append(deepest)
        self.weight_n[b] = max(weight[x] for x in self.objects)
        palm = 0.0
        for (a, c), f in forces.items():
            w = max(weight[x] for x in (a, c) if x in self.objects)
            if f / w > self.peak_w[b]:
                self.peak_w[b], self.peak_n[b], self.peak_step[b] = f / w, f, t
                self.peak_pair[b] = f"{names[a]}|{names[c]}"
            if hand in (a, c):
                palm += f
        if split[:, 0].any():
            self.palm_steps[b] += 1
            self.palm_force[b] = max(self.palm_force[b], palm)
        for k in range(2):
            if split[k, 0]:
                self.palm_split_steps[b, k] += 1
                self.palm_split_force[b, k] = max(self.palm_split_force[b, k], split[k, 1])
        if deepest > self.pen[b]:
            self.pen[b] = deepest
            self.pen_pair[b] = f"{names[where[0]]}|{names[where[1]]}"
        speed = []
        for body in self.objects:  # cvel: the velocities of this step's forward pass, as xipos
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body, self._vel, 0)
            speed.append(float(np.linalg.norm(self._vel[3:])))
        held = held_bodies(m, d, hand)
        self.speeds[b].append((speed[0], speed[1]))
        self.held[b].append((self.objects[0] in held, self.objects[1] in held))
        assert len(self.speeds[b]) == t + 1, "observe every step of a rollout in order"

    def result(self, measure: int | np.ndarray) -> dict[str, Any]:
        """``measure``: the step the goal is read at, one for all rollouts or (B,) per rollout
        (programs v2 read each at rest: ``replay_native``'s ``read_step``)."""
        ms = np.broadcast_to(np.asarray(measure, int), (len(self.speeds),))
        at = np.asarray([s[m] if m < len(s) else (np.nan, np.nan) for s, m in zip(self.speeds, ms)]).reshape(-1, 2)
        held = np.asarray([h[m] if m < len(h) else (False, False) for h, m in zip(self.held, ms)]).reshape(-1, 2)
        end = np.asarray([max(s[-1]) if s else np.nan for s in self.speeds])
        press = np.asarray([held_peak(s, SUSTAIN_STEPS) for s in self.load])
        held_pen = np.asarray([held_peak(s, SUSTAIN_STEPS) for s in self.depth])
        with np.errstate(divide="ignore", invalid="ignore"):
            press_w = np.where(self.weight_n > 0, press / self.weight_n, 0.0)
        return dict(palm_contact=self.palm_steps > 0, palm_steps=self.palm_steps,
                    palm_seconds=self.palm_steps * self.timestep,
                    palm_force_n=self.palm_force, palm_top_steps=self.palm_split_steps[:, 0].copy(),
                    palm_top_force_n=self.palm_split_force[:, 0].copy(),
                    palm_side_steps=self.palm_split_steps[:, 1].copy(),
                    palm_side_force_n=self.palm_split_force[:, 1].copy(), peak_force_n=self.peak_n, peak_force_weights=self.peak_w,
                    peak_pair=self.peak_pair.astype(str), peak_step=self.peak_step,
                    max_penetration_m=self.pen, penetration_pair=self.pen_pair.astype(str),
                    held_penetration_m=held_pen,
                    speed_toy=at[:, 0], speed_other=at[:, 1], held_toy=held[:, 0], held_other=held[:, 1],
                    speed_end=end, object_peak_n=np.asarray([max(s) if s else 0.0 for s in self.load]),
                    press_n=press, weight_n=self.weight_n.copy(), press_weights=press_w)


def held_peak(series: list[float] | np.ndarray, steps: int) -> float:
    """The largest value held over ``steps`` consecutive entries of ``series`` (the minimum
    over a window, maximised over windows); 0.0 for a series shorter than ``steps``."""
    s = np.asarray(series, float)
    if len(s) < steps:
        return 0.0
    return float(np.lib.stride_tricks.sliding_window_view(s, steps).min(axis=-1).max())

