"""The nine actions of the paper (Table I) as motor programs on settled scenes, labelled by physics.

Takes settled scenes (``scenes.py`` on the arm-less world) and the action world
(``world.build_world(arm=True)``: the same pairs plus the arm of ``scenes/arm.xml``); gives, per
scene, whether the action's goal was reached (the affordance label) and diagnostics.

Pipeline of one batch (two compiled programs per batch shape, plan and simulate, shared by
all nine actions: the action index is traced):
  1. ``plan``: tcp waypoints from the settled object poses (``_program_*``), solved by the
     batched IK (``arm.solve_ik_path``) from the arm's home pose. No path planning (paper IV-D):
     if any waypoint is unreachable or badly conditioned, or the object does not fit the
     gripper, the action is *infeasible*: the arm stays home and the label is False.
  2. ``simulate``: the waypoints become actuator commands (``arm.program_ctrl``) executed in
     MJX with ``lax.scan`` over time, vmapped over scenes with per-pair models.
  3. ``label``: outcome rules of Table I on the objects' centres of mass (thresholds in
     ``ActionConfig``). The toy is never moved by script, only by contacts.

Settled scenes map into the action world one to one: both worlds put the toy's and the other
object's free joints first (qpos 0..13), the arm's joints follow. The arm starts at its home
pose holding the rake's grip point (``PhysicsConfig.held_rake_pos``); in rake scenes the rake is
attached to the hand by the weld ``tool_grip`` (the paper: rakes are "attached to the robot arm
as a tool"); every other grasp is the pads' friction plus a grasp lock that engages only while
the fingers close with both pads' faces on the grasped body (``_simulate``).

Public API: ``ACTIONS``, ``ActionConfig``, ``make_plan_fn``, ``make_action_fn``,
``make_rollout_fn(action, batch, config)`` (for ``dataset.generate_dataset``),
``replay_native`` (MuJoCo C replay of a plan, for cross-checks). Motor programs: docs/actions.md.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from . import arm as A
from . import objects as lib
from . import scenes as sc
from . import world as wd

from relaff_jax.constants import ACTIONS, PAIRING, action_id  # noqa: F401 (re-exported)


@dataclasses.dataclass(frozen=True)
class ActionConfig:
    """Static settings of the motor programs and of the outcome rules (lengths in metres)."""

    lift_height: float = 0.25  # lift/take/pour/slide raise the tcp this much
    tilt_deg: float = 60.0  # pour/slide tilt (tan 60 deg > every friction coefficient)
    drag_raise: float = 0.02  # pull/push/unobstruct carry the object this high
    pull_distance: float = 0.25
    push_distance: float = 0.25
    unobstruct_distance: float = 0.30
    move_distance: float = 0.25  # move: the fingers end this far beyond their start beside the toy
    rake_pull: float = 0.30
    clearance: float = 0.10  # transit height of the fingertips above the highest object
    grip_margin: float = 0.02  # pre-grasp opening beyond the object's half width, per finger
    tip_clearance: float = 0.005  # fingertips this far above the grasped object's bottom
    rake_gap: float = 0.02  # gap between the toy and the rake head / the sweeping fingers
    # outcome thresholds
    lifted: float = 0.05  # "lifted": the centre of mass rose at least this much
    moved: float = 0.03  # slide: the toy moved at least this much (and was not lifted)
    closer: float = 0.10  # pull, rake: horizontal distance to the robot shrank this much
    farther: float = 0.10  # push: grew this much
    aside: float = 0.08  # move: the toy displaced along the sweep, relative to the base, this much
    move_rule: str = "apart"  # "apart": toy moved aside from the base; "both": both moved aside
    take_opening: float = 0.05  # take: fixed pre-grasp half opening (10 cm between the pads)
    take_align: bool = False  # take: turn the wrist to the toy's narrow side (False: closing
    # axis across the robot's line of sight, whatever the toy's yaw)
    corridor: float = 0.05  # unobstruct: clearance of the approach corridor (see docs)
    arm: A.ArmConfig = A.ArmConfig()
    phys: wd.PhysicsConfig = wd.PhysicsConfig()
    scene: sc.SceneConfig = sc.SceneConfig()


class Template(NamedTuple):
    """Static part of a motor program: per segment its length (control steps of one physics
    step), the IK target it ends at (index into the planned targets) and whether the fingers
    close (True) or open to the pre-grasp width (False) during it; ``measure``: the control
    step at which lift-type goals are read (the end of the action's own program).

    Every template is padded to ``N_SEGMENTS`` segments and ``N_STEPS`` control steps (a final
    rest), so one compiled simulation serves all nine actions."""

    seg_steps: tuple[int, ...]
    target: tuple[int, ...]
    closed: tuple[bool, ...]
    measure: int


N_SEGMENTS = 11
N_STEPS = 815  # 3.26 s at the 4 ms step (the longest template, pour/slide, plus padding)
N_TARGETS = 6


def _template(rows) -> Template:
    steps, target, closed = (list(c) for c in zip(*rows))
    measure = sum(steps) - 1
    while len(steps) < N_SEGMENTS:  # 1-step dwells, then the last one rests until N_STEPS
        steps.append(1)
        target.append(target[-1])
        closed.append(closed[-1])
    steps[-1] += N_STEPS - sum(steps)
    assert len(steps) == N_SEGMENTS and min(steps) >= 1, rows
    return Template(tuple(steps), tuple(target), tuple(closed), measure)


# Grasp-and-lift: home -> above (0), down to the grasp (1), dwell, close, lift (2), hold.
_LIFT = [(150, 0, False), (100, 1, False), (40, 1, False), (60, 1, True), (25, 1, True),
         (125, 2, True), (60, 2, True)]
# Pour/slide: the same, then tilt (3) and hold while a loose toy slides off and lands.
_TILT = _LIFT + [(100, 3, True), (150, 3, True)]
# Carry along the table: grasp, raise a little (2), carry (3), lower (4), open, retreat (5).
_DRAG = _LIFT[:5] + [(40, 2, True), (150, 3, True), (40, 4, True), (40, 4, False), (60, 5, False),
                     (50, 5, False)]
# Rake: with the held rake above the start (0), down (1), pull (2), retreat (3); slow enough
# that the head drags the toy instead of tipping it over.
_SWEEP = [(150, 0, True), (100, 1, True), (30, 1, True), (250, 2, True), (30, 2, True),
          (60, 3, True), (30, 3, True)]
# Move: the same with the closed gripper and a slower sweep (1.6 s), a push rather than a blow.
_MOVE = _SWEEP[:3] + [(400, 2, True)] + _SWEEP[4:]
TEMPLATES = {
    "lift": _template(_LIFT), "move": _template(_MOVE), "pull": _template(_DRAG),
    "push": _template(_DRAG), "rake": _template(_SWEEP), "take": _template(_LIFT),
    "pour": _template(_TILT), "slide": _template(_TILT), "unobstruct": _template(_DRAG),
}
_TPL_STEPS = np.asarray([TEMPLATES[a].seg_steps for a in ACTIONS], np.int32)  # (9, S)
_TPL_TARGET = np.asarray([TEMPLATES[a].target for a in ACTIONS], np.int32)
_TPL_CLOSED = np.asarray([TEMPLATES[a].closed for a in ACTIONS], bool)
_TPL_MEASURE = np.asarray([TEMPLATES[a].measure for a in ACTIONS], np.int32)
_RAKE = ACTIONS.index("rake")
_UNOBSTRUCT = ACTIONS.index("unobstruct")
# Which body a closed gripper locks onto (0 none, 1 the other object, 2 the toy); see _simulate.
_GRASPS = np.asarray([{"take": 2, "move": 0, "rake": 0}.get(a, 1) for a in ACTIONS], np.int32)


@dataclasses.dataclass(frozen=True, eq=False)
class Geometry:
    """Per-pair object geometry in each object's own frame (origin at the footprint's bottom
    centre; rakes: the grip point). (P, 3) bounding boxes ``toy_lo``/``toy_hi`` and
    ``oth_lo``/``oth_hi``; rake head: ``head_x0`` near face x, ``head_y`` (P, 2) y range."""

    pairing: np.ndarray
    toy_lo: np.ndarray
    toy_hi: np.ndarray
    oth_lo: np.ndarray
    oth_hi: np.ndarray
    head_x0: np.ndarray
    head_y: np.ndarray


def _bbox(spec: lib.ObjectSpec) -> tuple[np.ndarray, np.ndarray]:
    if spec.sphere_radius:
        r = spec.sphere_radius
        return np.array([-r, -r, 0.0]), np.array([r, r, 2 * r])
    lo = np.min([np.subtract(b.centre, np.divide(b.size, 2)) for _, b in spec.parts], axis=0)
    hi = np.max([np.add(b.centre, np.divide(b.size, 2)) for _, b in spec.parts], axis=0)
    return lo, hi


@functools.lru_cache(maxsize=4)
def geometry(world: wd.World) -> Geometry:
    rows = []
    for toy, other, pairing in world.pairs:
        t, o = lib.get(toy), lib.get(other)
        (tl, th), (ol, oh) = _bbox(t), _bbox(o)
        head_x0, head_y = 0.0, (0.0, 0.0)
        if o.kind == "rake":
            head = dict(o.parts)["wall_xp"]
            head_x0 = head.centre[0] - head.size[0] / 2
            head_y = (head.centre[1] - head.size[1] / 2, head.centre[1] + head.size[1] / 2)
        rows.append((lib.PAIRINGS.index(pairing), tl, th, ol, oh, head_x0, head_y))
    cols = list(zip(*rows))
    return Geometry(np.asarray(cols[0], np.int32), *(np.asarray(c, np.float32) for c in cols[1:]))


# ------------------------------------------------------------------------- scene geometry


def _quat_mat(q: jax.Array) -> jax.Array:
    w, x, y, z = q / jnp.linalg.norm(q)
    return jnp.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


class Body(NamedTuple):
    """World-frame view of one object: origin ``pos``, ``mat``, box ``lo``/``hi`` (own frame)."""

    pos: jax.Array
    mat: jax.Array
    lo: jax.Array
    hi: jax.Array

    @property
    def centre(self) -> jax.Array:
        return self.pos + self.mat @ ((self.lo + self.hi) / 2)

    def z_range(self) -> tuple[jax.Array, jax.Array]:
        signs = jnp.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], jnp.float32)
        corners = self.lo + signs * (self.hi - self.lo)
        z = self.pos[2] + corners @ self.mat[2]
        return z.min(), z.max()

    def half_width(self, direction: jax.Array) -> jax.Array:
        """Half extent of the box along a world direction (3,) (its support)."""
        return jnp.sum(jnp.abs(self.mat.T @ direction) * (self.hi - self.lo) / 2)


def _bodies(geo: Geometry, pair: jax.Array, qpos: jax.Array) -> tuple[Body, Body]:
    g = lambda a: jnp.asarray(a)[pair]
    toy = Body(qpos[0:3], _quat_mat(qpos[3:7]), g(geo.toy_lo), g(geo.toy_hi))
    oth = Body(qpos[7:10], _quat_mat(qpos[10:14]), g(geo.oth_lo), g(geo.oth_hi))
    return toy, oth


def _unit_xy(v: jax.Array) -> jax.Array:
    v = jnp.array([v[0], v[1], 0.0])
    n = jnp.linalg.norm(v)
    return jnp.where(n > 1e-6, v / jnp.maximum(n, 1e-6), jnp.array([1.0, 0.0, 0.0]))


def _perp(u: jax.Array) -> jax.Array:
    return jnp.array([-u[1], u[0], 0.0])


DOWN = jnp.array([0.0, 0.0, -1.0])


def _td(pos, closing) -> A.IKTarget:
    """Top-down target with a sign-free closing axis."""
    return A.IKTarget(pos, DOWN, closing, jnp.asarray(1.0), jnp.asarray(0.0))


def _stack(targets: list[A.IKTarget]) -> A.IKTarget:
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *targets)


class Grasp(NamedTuple):
    xy: jax.Array  # (3,) grasp point with z = 0
    tcp_z: jax.Array  # tcp height at the grasp
    closing: jax.Array  # (3,) horizontal closing axis
    opening: jax.Array  # pre-grasp half opening
    fits: jax.Array  # bool: the gripper opens wide enough


def _grasp(arm: A.Arm, cfg: ActionConfig, body: Body) -> Grasp:
    """Top-down grasp across the narrower horizontal side of a body's box."""
    ax, ay = _unit_xy(body.mat[:, 0]), _unit_xy(body.mat[:, 1])
    wx, wy = body.half_width(ax), body.half_width(ay)
    closing = jnp.where(wx <= wy, ax, ay)
    half = jnp.minimum(wx, wy)
    zmin, zmax = body.z_range()
    tip = zmin + jnp.minimum(cfg.tip_clearance, 0.4 * (zmax - zmin))
    opening = half + cfg.grip_margin
    c = body.centre
    return Grasp(jnp.array([c[0], c[1], 0.0]), tip + arm.tip_below_tcp, closing, opening,
                 opening <= float(arm.finger_range[1]))


# -------------------------------------------------------------------------- motor programs


class Program(NamedTuple):
    """Per-scene part of a motor program (single scene)."""

    targets: A.IKTarget  # (K,) tcp targets
    opening: jax.Array  # () pre-grasp half opening
    ok: jax.Array  # () bool: geometric preconditions (object fits the gripper, ...)
    direction: jax.Array  # (3,) the action's horizontal direction (move/pull/push/...), or 0


def _take_grasp(arm: A.Arm, cfg: ActionConfig, toy: Body) -> Grasp:
    """Take's grasp: top-down at the toy's centre with a fixed pre-grasp opening
    (``cfg.take_opening``) and, unless ``cfg.take_align``, the closing axis across the line
    from the robot, whatever the toy's yaw. A toy wider than the opening along that axis
    meets the pads as they come down; physics decides whether they turn it into the gap or
    miss (the grasp lock needs both pads' faces on the toy). In a container the pads must also fit beside the toy."""
    g = _grasp(arm, cfg, toy)
    if cfg.take_align:
        closing = g.closing
    else:
        closing = _perp(_unit_xy(toy.centre))
    opening = jnp.asarray(cfg.take_opening, jnp.float32)
    return g._replace(closing=closing, opening=opening, fits=opening <= float(arm.finger_range[1]))


def _transit_z(arm: A.Arm, cfg: ActionConfig, toy: Body, oth: Body) -> jax.Array:
    return jnp.maximum(toy.z_range()[1], oth.z_range()[1]) + cfg.clearance + arm.tip_below_tcp


def _program_lift(arm, cfg, toy, oth, *, grasp_toy: bool, tilt: bool) -> Program:
    g = _take_grasp(arm, cfg, toy) if grasp_toy else _grasp(arm, cfg, oth)
    up = jnp.maximum(_transit_z(arm, cfg, toy, oth), g.tcp_z + 0.05)
    pos = lambda z: g.xy + jnp.array([0.0, 0.0, 1.0]) * z
    targets = [_td(pos(up), g.closing), _td(pos(g.tcp_z), g.closing),
               _td(pos(g.tcp_z + cfg.lift_height), g.closing)]
    if tilt:
        # tilt about the closing axis: the surface slopes along the pads' faces, so nothing
        # slides into a finger (a finger would act as a wall and keep the toy); lean the tool
        # towards the robot, the side the arm reaches more easily
        rot = A._axis_rotation(g.closing, jnp.deg2rad(cfg.tilt_deg))
        lean_out = jnp.dot(rot @ DOWN, _unit_xy(g.xy)) > 0
        rot = jnp.where(lean_out, rot.T, rot)
        targets.append(A.IKTarget(pos(g.tcp_z + cfg.lift_height), rot @ DOWN, rot @ g.closing,
                                  jnp.asarray(1.0), jnp.asarray(0.0)))
    return Program(_stack(targets), g.opening, g.fits, jnp.zeros(3))


def _program_drag(arm, cfg, toy, oth, *, direction: jax.Array, distance: float, raise_by: float) -> Program:
    g = _grasp(arm, cfg, oth)
    up = jnp.maximum(_transit_z(arm, cfg, toy, oth), g.tcp_z + 0.05)
    z = jnp.array([0.0, 0.0, 1.0])
    end = g.xy + direction * distance
    targets = [_td(g.xy + z * up, g.closing), _td(g.xy + z * g.tcp_z, g.closing),
               _td(g.xy + z * (g.tcp_z + raise_by), g.closing),
               _td(end + z * (g.tcp_z + raise_by), g.closing), _td(end + z * g.tcp_z, g.closing),
               _td(end + z * (g.tcp_z + 0.10), g.closing)]
    return Program(_stack(targets), g.opening, g.fits, direction)


def _exit_distance(p: jax.Array, d: jax.Array, body: Body, margin: float) -> jax.Array:
    """Smallest s >= 0 such that ``p - s * d`` (xy) lies outside the body's footprint
    rectangle grown by ``margin`` (0 if it is outside already). p, d: (3,) horizontal."""
    ax = _unit_xy(body.mat[:, 0])
    ay = _perp(ax)
    half = jnp.stack([body.half_width(ax), body.half_width(ay)]) + margin
    rel = p - body.centre
    o = jnp.stack([rel @ ax, rel @ ay])  # start in the box frame
    v = -jnp.stack([d @ ax, d @ ay])  # walking direction in the box frame
    safe = jnp.where(jnp.abs(v) > 1e-6, v, 1e-6)
    t_out = jnp.min(jnp.maximum((-half - o) / safe, (half - o) / safe))  # leaves the last slab
    inside = jnp.all(jnp.abs(o) < half)
    return jnp.where(inside, jnp.maximum(t_out, 0.0), 0.0)


def _program_move(arm, cfg, toy, oth) -> Program:
    """Sweep the toy aside along the table: the closed gripper comes down on free table
    beside the toy, fingertips just above the table, and sweeps across the toy's place to
    ``cfg.move_distance`` beyond that start (further if the start had to step back), at right angles to the line from the toy to the other object (across the
    robot's line of sight if their centres nearly coincide), towards the robot's side.

    The program knows where the toy is, not what it stands on: if the toy's side lies over
    the other object, the descent point moves out along the sweep line until it is over free
    table, and the sweep then meets the other object first."""
    c = toy.centre
    c = jnp.array([c[0], c[1], 0.0])
    towards = oth.centre - toy.centre
    far = jnp.linalg.norm(towards[:2]) > 0.02
    d = _perp(jnp.where(far, _unit_xy(towards), _unit_xy(c)))
    d = jnp.where(jnp.dot(d, c) > 0, -d, d)  # the end nearer the robot
    reach = toy.half_width(d) + arm.pad_thickness + cfg.rake_gap
    finger = arm.pad_thickness + cfg.rake_gap  # half the closed fingers' footprint, plus a gap
    start = c - d * reach
    start = start - d * _exit_distance(start, d, oth, finger)
    tcp_z = cfg.tip_clearance + 0.005 + arm.tip_below_tcp  # fingertips 1 cm above the table
    up = _transit_z(arm, cfg, toy, oth)
    z = jnp.array([0.0, 0.0, 1.0])
    end = c + d * (cfg.move_distance - reach)
    targets = [_td(start + z * up, d), _td(start + z * tcp_z, d), _td(end + z * tcp_z, d),
               _td(end + z * (tcp_z + 0.10), d)]
    return Program(_stack(targets), jnp.asarray(0.0), jnp.asarray(True), d)


def _program_rake(arm, cfg, toy, geo_head_x0, geo_head_y) -> Program:
    """Put the rake head behind the toy (seen from the robot), beside the handle, and pull."""
    radial = _unit_xy(toy.centre)
    side = _perp(radial)
    tool_mat = jnp.stack([radial, side, jnp.array([0.0, 0.0, 1.0])], axis=1)
    # toy centre in the tool frame: in front of the head's near face, beside the handle
    x_t = geo_head_x0 - toy.half_width(radial) - cfg.rake_gap
    handle_half = 0.0125
    y_t = handle_half + cfg.rake_gap + toy.half_width(side)
    c = toy.centre
    origin = jnp.array([c[0], c[1], 0.0]) - radial * x_t - side * y_t
    low = origin + jnp.array([0.0, 0.0, 0.003])
    above = origin + jnp.array([0.0, 0.0, toy.z_range()[1] + cfg.clearance])
    pulled = low - radial * cfg.rake_pull
    raised = pulled + jnp.array([0.0, 0.0, 0.10])
    targets = [A.tool_tcp_target(p, tool_mat) for p in (above, low, pulled, raised)]
    # the toy must lie within the head's lateral extent to be caught at all
    covers = y_t - toy.half_width(side) < geo_head_y[1]
    return Program(_stack(targets), jnp.asarray(0.0), covers, -radial)


def _corridor_blocked(cfg: ActionConfig, toy: Body, obst: Body, min_radius: float) -> jax.Array:
    """Is the straight approach from the robot to the toy blocked by the obstacle?

    The corridor is the segment from the robot (at ``min_radius`` on the line to the toy) to
    the toy's centre, widened by the toy's half width plus ``cfg.corridor``; blocked when the
    obstacle's footprint rectangle comes closer to the segment than that.
    """
    radial = _unit_xy(toy.centre)
    c = toy.centre
    p1 = jnp.array([c[0], c[1]])
    p0 = radial[:2] * min_radius
    s = jnp.linspace(0.0, 1.0, 24)[:, None]
    pts = p0 + s * (p1 - p0)
    ax = _unit_xy(obst.mat[:, 0])[:2]
    ay = jnp.array([-ax[1], ax[0]])
    oc = obst.centre[:2]
    local = jnp.stack([(pts - oc) @ ax, (pts - oc) @ ay], -1)
    half = jnp.stack([obst.half_width(jnp.array([ax[0], ax[1], 0.0])),
                      obst.half_width(jnp.array([ay[0], ay[1], 0.0]))])
    dist = jnp.linalg.norm(jnp.maximum(jnp.abs(local) - half, 0.0), axis=-1)
    width = toy.half_width(jnp.array([-radial[1], radial[0], 0.0])) + cfg.corridor
    return jnp.min(dist) < width


def toy_reachable(arm: A.Arm, cfg: ActionConfig, geo: Geometry, pair: jax.Array, qpos: jax.Array) -> jax.Array:
    """Unobstruct's reachability of the toy (one scene): a top-down grasp of the toy is
    reachable by the IK **and** the approach corridor from the robot is clear of the obstacle."""
    toy, obst = _bodies(geo, pair, qpos)
    g = _grasp(arm, cfg, toy)
    res = A.solve_ik(arm, cfg.arm, _td(g.xy + jnp.array([0.0, 0.0, 1.0]) * g.tcp_z, g.closing),
                     jnp.zeros(6))
    return res.reachable & g.fits & ~_corridor_blocked(cfg, toy, obst, cfg.scene.min_radius)


def program(action: str, arm: A.Arm, cfg: ActionConfig, geo: Geometry, pair: jax.Array,
            qpos: jax.Array) -> Program:
    """The per-scene motor program of ``action`` from the settled ``qpos`` (nq,) (one scene);
    its targets padded to ``N_TARGETS`` by repeating the last one."""
    toy, oth = _bodies(geo, pair, qpos)
    if action in ("lift", "take", "pour", "slide"):
        prog = _program_lift(arm, cfg, toy, oth, grasp_toy=action == "take",
                             tilt=action in ("pour", "slide"))
    elif action in ("pull", "push"):
        radial = _unit_xy(oth.centre)
        sign = -1.0 if action == "pull" else 1.0
        dist = cfg.pull_distance if action == "pull" else cfg.push_distance
        prog = _program_drag(arm, cfg, toy, oth, direction=sign * radial, distance=dist,
                             raise_by=cfg.drag_raise)
    elif action == "unobstruct":
        side = _perp(_unit_xy(toy.centre))
        d = jnp.where(jnp.dot(oth.centre, side) >= jnp.dot(toy.centre, side), 1.0, -1.0) * side
        prog = _program_drag(arm, cfg, toy, oth, direction=d, distance=cfg.unobstruct_distance,
                             raise_by=cfg.drag_raise + 0.01)
    elif action == "move":
        prog = _program_move(arm, cfg, toy, oth)
    elif action == "rake":
        prog = _program_rake(arm, cfg, toy, jnp.asarray(geo.head_x0)[pair], jnp.asarray(geo.head_y)[pair])
    else:
        raise ValueError(f"unknown action {action!r}; valid actions: {', '.join(ACTIONS)}")
    k = prog.targets.pos.shape[0]
    pad = lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], N_TARGETS - k, axis=0)])
    return prog._replace(targets=jax.tree_util.tree_map(pad, prog.targets))


# ---------------------------------------------------------------------------- planning


class Setup(NamedTuple):
    """Static pieces shared by planning, simulation and replay (built once in Python)."""

    world: wd.World
    arm: A.Arm
    geo: Geometry
    q_home: np.ndarray  # (6,) home pose: the tcp at the held rake's grip point


@functools.lru_cache(maxsize=4)
def setup(cfg: ActionConfig = ActionConfig()) -> Setup:
    world = wd.build_world(cfg.phys, arm=True)
    arm = A.arm_from_model(world.mj_model)
    held = jnp.asarray(cfg.phys.held_rake_pos, jnp.float32)
    home = jax.jit(functools.partial(A.solve_ik, arm, cfg.arm))(
        A.tool_tcp_target(held, jnp.eye(3)), jnp.zeros(6))
    if not bool(home.reachable):
        raise RuntimeError(f"the held rake pose {cfg.phys.held_rake_pos} is not reachable by the arm")
    return Setup(world, arm, geometry(world), np.asarray(home.q))


def _grip_home(cfg: ActionConfig) -> np.ndarray:
    """(9,) finger command at the start: closed on the rake's handle, else half open."""
    return np.where(np.asarray(ACTIONS) == "rake", cfg.arm.grip_closed, 0.06).astype(np.float32)


def _finger_home(action_id: jax.Array) -> jax.Array:
    """Finger joint value at the start: on the 2.5 cm handle for the rake, else 6 cm."""
    return jnp.where(action_id == _RAKE, 0.0125, 0.06)


class Plan(NamedTuple):
    """Joint-space program of a batch: ``q_way`` (B, S+1, 6), ``grip_way`` (B, S+1),
    ``seg_steps`` (S,) segment lengths, ``feasible`` (B,) bool, ``direction`` (B, 3) the
    action's horizontal direction, ``ik_error`` (B,) largest tcp residual of the IK (m)."""

    q_way: jax.Array
    grip_way: jax.Array
    seg_steps: jax.Array
    feasible: jax.Array
    direction: jax.Array
    ik_error: jax.Array


def make_plan_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``plan_fn(action_id (), pair (B,), qpos (B, nq)) -> Plan`` for any of the nine actions
    (``action_id`` indexes ``ACTIONS``; traced, so one compile serves all). Pure; caller jits."""
    st = setup(cfg)
    q_home = jnp.asarray(st.q_home, jnp.float32)
    grip_home = jnp.asarray(_grip_home(cfg))
    branches = [functools.partial(program, a, st.arm, cfg, st.geo) for a in ACTIONS]

    def one(action_id, pair, qpos):
        prog = jax.lax.switch(action_id, branches, pair, qpos)
        res = A.solve_ik_path(st.arm, cfg.arm, prog.targets, q_home)
        # only the targets the template uses count (the padding repeats the last one)
        used = jnp.arange(N_TARGETS) <= jnp.max(jnp.asarray(_TPL_TARGET)[action_id])
        feasible = jnp.all(res.reachable | ~used) & prog.ok
        q_way = jnp.concatenate([q_home[None], res.q[jnp.asarray(_TPL_TARGET)[action_id]]])
        opening = jnp.clip(prog.opening, 0.0, float(st.arm.finger_range[1]))
        grip = jnp.where(jnp.asarray(_TPL_CLOSED)[action_id], cfg.arm.grip_closed, opening)
        g0 = grip_home[action_id]
        grip_way = jnp.concatenate([g0[None], grip])
        # an infeasible program is not executed: the arm holds its home pose
        q_way = jnp.where(feasible, q_way, q_home[None])
        grip_way = jnp.where(feasible, grip_way, g0)
        return q_way, grip_way, feasible, prog.direction, jnp.max(jnp.where(used, res.pos_err, 0.0))

    def plan_fn(action_id, pair, qpos):
        action_id = jnp.asarray(action_id, jnp.int32)
        q_way, grip_way, feasible, direction, err = jax.vmap(one, in_axes=(None, 0, 0))(action_id, pair, qpos)
        return Plan(q_way, grip_way, jnp.asarray(_TPL_STEPS)[action_id], feasible, direction, err)

    return plan_fn


# ------------------------------------------------------------------------------ labels


class Outcome(NamedTuple):
    """Inputs of the outcome rules, per scene: centres of mass (2, 3) of (toy, other) before
    the action, at the measuring step and at the end; the action direction (3,); the
    unobstruct reachability before/after."""

    com0: jax.Array
    com_m: jax.Array
    com_end: jax.Array
    direction: jax.Array
    reach_before: jax.Array
    reach_after: jax.Array


def goals(cfg: ActionConfig, o: Outcome) -> jax.Array:
    """(9,) bool: the goal of every action of Table I (in ``ACTIONS`` order) on one scene."""
    rise = o.com_m[:, 2] - o.com0[:, 2]  # (2,) toy, other
    lifted = rise >= cfg.lifted
    r0 = jnp.linalg.norm(o.com0[:, :2], axis=-1)
    r1 = jnp.linalg.norm(o.com_end[:, :2], axis=-1)
    along = (o.com_end - o.com0) @ o.direction
    toy_moved = jnp.linalg.norm(o.com_m[0] - o.com0[0]) >= cfg.moved
    if cfg.move_rule == "apart":  # the toy moved aside from the base (the base left behind)
        move = along[0] - along[1] >= cfg.aside
    elif cfg.move_rule == "both":  # Table I read literally: both moved aside
        move = jnp.all(along >= cfg.aside)
    else:
        raise ValueError(f"unknown move_rule {cfg.move_rule!r}; valid: 'apart', 'both'")
    rules = {
        "lift": lifted[0] & lifted[1],  # base and toy lifted
        "move": move,  # toy and base moved aside (from each other, by default)
        "pull": jnp.all(r1 - r0 <= -cfg.closer),  # both pulled closer
        "push": jnp.all(r1 - r0 >= cfg.farther),  # both pushed further away
        "rake": r1[0] - r0[0] <= -cfg.closer,  # toy brought closer
        "take": lifted[0] & ~lifted[1],  # toy lifted (taken: its base, if any, left behind)
        "pour": lifted[0] & lifted[1],  # base and toy lifted (after the tilt)
        "slide": lifted[1] & toy_moved & ~lifted[0],  # base lifted, toy moved, not lifted
        "unobstruct": ~o.reach_before & o.reach_after,  # toy reachable now, not before
    }
    return jnp.stack([rules[a] for a in ACTIONS])


# -------------------------------------------------------------------------- simulation


def _initial_data(st: Setup, cfg: ActionConfig, action_id: jax.Array, qpos_obj: jax.Array,
                  qvel_obj: jax.Array):
    """Action-world data of one scene: settled objects (qpos[:14], qvel[:12]), arm at home."""
    d0 = mjx.make_data(st.world.mj_model)
    nqo, nvo = qpos_obj.shape[-1], qvel_obj.shape[-1]
    q_home = jnp.asarray(st.q_home, jnp.float32)
    qpos = A.set_arm_qpos(st.arm, d0.qpos.at[:nqo].set(qpos_obj), q_home, _finger_home(action_id))
    qvel = d0.qvel.at[:nvo].set(qvel_obj)
    ctrl = A.make_ctrl(st.arm, q_home, jnp.asarray(_grip_home(cfg))[action_id])
    # the rake is attached to the hand (weld "tool_grip") only in rake scenes
    eq = jnp.zeros(d0.eq_active.shape, bool).at[welds(st.world).tool].set(action_id == _RAKE)
    return d0.replace(qpos=qpos, qvel=qvel, ctrl=ctrl, eq_active=eq)


class Welds(NamedTuple):
    """Equality rows of the action world's hand welds and the geoms the grasp test uses."""

    tool: int
    obj: int
    toy: int
    hand_body: int
    toy_geoms: np.ndarray
    obj_geoms: np.ndarray


def welds(world: wd.World) -> Welds:
    m = world.mj_model
    eq = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, n)
    geoms = lambda b: np.nonzero(np.asarray(m.geom_bodyid) == b)[0]
    return Welds(eq("tool_grip"), eq("grasp_obj"), eq("grasp_toy"),
                 mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "arm_hand"),
                 geoms(world.toy_body), geoms(world.obj_body))


def _simulate(st: Setup, cfg: ActionConfig, w: Welds, grasp: jax.Array, mx, d, q_way, grip_way,
              seg_steps, closed, observe):
    """Run a program on one scene (``lax.scan`` over ``N_STEPS`` control steps) with grasp locks.

    A grasp lock is the weld ``grasp_obj``/``grasp_toy`` (``grasp`` 1/2 selects which, 0 none):
    it engages only during a segment that closes the fingers and only once *both* finger pads
    touch the grasped body (``arm.finger_contacts``), with the relative pose the two bodies
    have at that moment; it releases when a segment opens the fingers. A closed gripper that
    misses holds nothing. Returns the final data and ``observe(d)`` per control step.
    """
    arm = st.arm
    toy_b, obj_b = st.world.toy_body, st.world.obj_body

    def control_step(carry, t):
        d, eq_data = carry
        closing = jnp.asarray(closed)[A.segment_index(seg_steps, t)]
        touch_obj = jnp.all(A.finger_contacts(arm, cfg.arm, d, w.obj_geoms))
        touch_toy = jnp.all(A.finger_contacts(arm, cfg.arm, d, w.toy_geoms))
        active = d.eq_active
        lock_obj = closing & (grasp == 1) & (active[w.obj] | touch_obj)
        lock_toy = closing & (grasp == 2) & (active[w.toy] | touch_toy)
        new_obj = lock_obj & ~active[w.obj]
        new_toy = lock_toy & ~active[w.toy]
        rel_obj = A.weld_relpose(d.xpos[w.hand_body], d.xquat[w.hand_body], d.xpos[obj_b], d.xquat[obj_b])
        rel_toy = A.weld_relpose(d.xpos[w.hand_body], d.xquat[w.hand_body], d.xpos[toy_b], d.xquat[toy_b])
        eq_data = eq_data.at[w.obj, 3:10].set(jnp.where(new_obj, rel_obj, eq_data[w.obj, 3:10]))
        eq_data = eq_data.at[w.toy, 3:10].set(jnp.where(new_toy, rel_toy, eq_data[w.toy, 3:10]))
        active = active.at[w.obj].set(lock_obj).at[w.toy].set(lock_toy)
        d = d.replace(ctrl=A.program_ctrl(arm, q_way, grip_way, seg_steps, t), eq_active=active)
        d = mjx.step(mx.replace(eq_data=eq_data), d)
        return (d, eq_data), observe(d)

    (d, _), trace = jax.lax.scan(control_step, (d, jnp.asarray(mx.eq_data)), jnp.arange(N_STEPS))
    return d, trace


def make_prepare_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``prepare_fn(action_id (), pair (B,), qpos (B, 14)) -> (Plan, reach_before (B,))``: the
    motor program of every scene and, for unobstruct, whether the toy is reachable in the
    settled scene (False for the other actions). Pure; the caller jits."""
    st = setup(cfg)
    plan_fn = make_plan_fn(cfg)
    reach = jax.vmap(lambda p, q: toy_reachable(st.arm, cfg, st.geo, p, q))

    def prepare_fn(action_id, pair, qpos):
        action_id = jnp.asarray(action_id, jnp.int32)
        before = jax.lax.cond(action_id == _UNOBSTRUCT, lambda: reach(pair, qpos),
                              lambda: jnp.zeros(pair.shape, bool))
        return plan_fn(action_id, pair, qpos), before

    return prepare_fn


def make_simulate_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``simulate_fn(action_id (), pair (B,), qpos (B, 14), qvel (B, 12), plan, reach_before)
    -> dict``: execute planned programs in MJX and label the outcomes. Pure; caller jits.

    See ``make_action_fn`` for the inputs and the returned fields.
    """
    st = setup(cfg)
    world, arm = st.world, st.arm
    toy_b, obj_b = world.toy_body, world.obj_body
    observe = lambda d: jnp.stack([d.xipos[toy_b], d.xipos[obj_b]])
    forward = jax.vmap(mjx.forward, in_axes=(world.model_axes, 0))
    reach = jax.vmap(lambda p, q: toy_reachable(arm, cfg, st.geo, p, q))
    wl = welds(world)

    def simulate_fn(action_id, pair, qpos, qvel, plan, before):
        action_id = jnp.asarray(action_id, jnp.int32)
        models = wd.scene_models(world, pair)
        data = jax.vmap(lambda q, v: _initial_data(st, cfg, action_id, q, v))(qpos, qvel)
        data = forward(models, data)
        com0 = jnp.stack([data.xipos[:, toy_b], data.xipos[:, obj_b]], 1)
        grasp = jnp.asarray(_GRASPS)[action_id]
        closed = jnp.asarray(_TPL_CLOSED)[action_id]
        run = lambda mx, d, qw, gw: _simulate(st, cfg, wl, grasp, mx, d, qw, gw, plan.seg_steps,
                                              closed, observe)
        final, trace = jax.vmap(run, in_axes=(world.model_axes, 0, 0, 0))(
            models, data, plan.q_way, plan.grip_way)
        nqo = qpos.shape[-1]
        qpos_final = final.qpos[:, :nqo]
        after = jax.lax.cond(action_id == _UNOBSTRUCT, lambda: reach(pair, qpos_final),
                             lambda: jnp.zeros(pair.shape, bool))
        com_m = trace[:, jnp.asarray(_TPL_MEASURE)[action_id]]
        out = Outcome(com0, com_m, trace[:, -1], plan.direction, before, after)
        labels = jax.vmap(lambda o: goals(cfg, o))(out)[:, action_id] & plan.feasible
        return dict(label=labels, feasible=plan.feasible, ik_error=plan.ik_error, com0=com0,
                    com_m=com_m, com_end=out.com_end, reach_before=before, reach_after=after,
                    qpos_final=qpos_final, q_way=plan.q_way, grip_way=plan.grip_way,
                    seg_steps=plan.seg_steps)

    return simulate_fn


def make_action_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``action_fn(action_id (), pair (B,), qpos (B, 14), qvel (B, 12)) -> dict`` of per-scene
    results for any of the nine actions (pure; the caller jits; one compile per batch shape
    for all actions). ``qpos``/``qvel``: settled object states in the arm-less layout
    (``scenes.Scenes.qpos``/``qvel``). Composes ``make_prepare_fn`` and ``make_simulate_fn``.

    Returns ``label`` (B,) bool, ``feasible``, ``ik_error``, ``com0``/``com_m``/``com_end``
    (B, 2, 3) centres of mass of (toy, other), ``reach_before``/``reach_after`` (unobstruct),
    ``qpos_final`` (B, 14) and the plan (``q_way``, ``grip_way``, ``seg_steps``).
    """
    prepare_fn, simulate_fn = make_prepare_fn(cfg), make_simulate_fn(cfg)

    def action_fn(action_id, pair, qpos, qvel):
        plan, before = prepare_fn(action_id, pair, qpos)
        return simulate_fn(action_id, pair, qpos, qvel, plan, before)

    return action_fn


@functools.lru_cache(maxsize=4)
def jitted_stage_fns(cfg: ActionConfig = ActionConfig()) -> tuple[Callable, Callable]:
    """The jitted ``make_prepare_fn(cfg)`` and ``make_simulate_fn(cfg)``, cached: each compiles
    once per batch shape and serves all nine actions (the action index is traced)."""
    return jax.jit(make_prepare_fn(cfg)), jax.jit(make_simulate_fn(cfg))


def jitted_action_fn(cfg: ActionConfig = ActionConfig()) -> Callable:
    """``action_fn`` built from the two cached jitted stages (``jitted_stage_fns``), so that
    it shares its compiled programs with ``make_rollout_fn``: two programs per batch shape
    (plan, simulate), for all actions."""
    prepare_fn, simulate_fn = jitted_stage_fns(cfg)

    def action_fn(action_id, pair, qpos, qvel):
        plan, before = prepare_fn(action_id, pair, qpos)
        return simulate_fn(action_id, pair, qpos, qvel, plan, before)

    return action_fn


# ----------------------------------------------------------------- dataset rollouts


def allowed_pairs(world: wd.World, action: str) -> np.ndarray:
    """Pair indices whose pairing the action uses (toy+base, toy+obstacle or toy+rake)."""
    return np.nonzero(geometry(world).pairing == PAIRING[action])[0]


def default_sim_batch(batch: int) -> int:
    """Scenes per simulation call in ``make_rollout_fn``: 16 (or ``batch`` if smaller).

    MJX on the CPU simulates about the same number of scenes per second at 16 and 32 (2.6
    scenes/s, docs/actions.md) and fewer at 8, so 16 keeps the padding of a chunk's last call
    small (about 40 % of a chunk is feasible: a chunk of 32 needs one call)."""
    return min(int(batch), 16)


def make_rollout_fn(action: str, batch: int, config: ActionConfig | None = None,
                    sim_batch: int | None = None) -> Callable:
    """``rollout_fn(key, batch_size) -> dict`` of numpy arrays per sample, for
    ``dataset.generate_dataset``: samples pairs of the action's pairing, places and settles
    the scenes (``scenes.jitted_scene_fns`` on the arm-less world), plans the action, runs the
    feasible programs, labels.

    Only feasible programs are simulated, in calls of ``sim_batch`` scenes (default
    ``default_sim_batch(batch)`` = 16; the last call is padded with repeats of its scenes). An
    infeasible program is not executed (the arm stays home, ``make_plan_fn``) and its label is
    False by definition, so skipping its simulation changes no label; its ``qpos_final`` is
    the settled state and ``reach_after`` equals ``reach_before``. About 60 % of the sampled
    scenes are infeasible (out of the arm's 1.2 m reach in the 1.8 m workspace), so this
    simulates ~2.5x fewer scenes. ``tests/test_actions.py`` checks the labels against running
    every scene.

    Fields: ``label``, ``relation`` (int codes into ``scenes.RELATIONS``), ``cog_distance``,
    ``toy``, ``other`` (names), ``pair`` (int32), ``qpos0`` / ``qpos_settled`` (float32 (14,),
    arm-less layout), ``qpos_final``, ``rollout_id`` (int64), ``intended``, ``at_rest``,
    ``feasible``, ``ik_error``, ``reach_before``/``reach_after``, ``simulated`` (bool: the
    program ran in MJX).
    ``batch`` is the batch size the caller will use (compiled on the first call).
    """
    aid = action_id(action)
    if int(batch) < 1:
        raise ValueError(f"batch must be >= 1, got {batch}")
    sim_batch = default_sim_batch(batch) if sim_batch is None else int(sim_batch)
    if sim_batch < 1:
        raise ValueError(f"sim_batch must be >= 1, got {sim_batch}")
    cfg = config or ActionConfig()
    scene_world = wd.build_world(cfg.phys)
    place_fn, settle_fn, _ = sc.jitted_scene_fns(scene_world, cfg.scene)
    prepare_fn, simulate_fn = jitted_stage_fns(cfg)
    allowed = allowed_pairs(scene_world, action)
    names = np.asarray([(t, o) for t, o, _ in scene_world.pairs])

    def rollout_fn(key, batch_size: int) -> dict[str, np.ndarray]:
        kp, ks, kid = jax.random.split(key, 3)
        pair = sc.sample_pairs(kp, allowed, scene_world, int(batch_size))
        qpos0, intended = place_fn(ks, pair)
        scenes = settle_fn(pair, qpos0, intended)
        plan, before = prepare_fn(aid, pair, scenes.qpos)
        s, plan, before = jax.device_get((scenes, plan, before))
        p = np.asarray(pair)
        qpos = np.asarray(s.qpos, np.float32)
        # not executed: label False, objects where they settled
        label = np.zeros(len(p), bool)
        qpos_final = qpos.copy()
        after = np.asarray(before, bool).copy()
        run = np.flatnonzero(plan.feasible)
        for lo in range(0, len(run), sim_batch):
            rows = run[lo:lo + sim_batch]
            idx = np.resize(rows, sim_batch)  # pad with repeats: one compiled shape
            sub = Plan(plan.q_way[idx], plan.grip_way[idx], plan.seg_steps, plan.feasible[idx],
                       plan.direction[idx], plan.ik_error[idx])
            out = jax.device_get(simulate_fn(aid, p[idx], qpos[idx], np.asarray(s.qvel)[idx], sub,
                                             np.asarray(before)[idx]))
            k = len(rows)
            label[rows] = out["label"][:k]
            qpos_final[rows] = out["qpos_final"][:k]
            after[rows] = out["reach_after"][:k]
        simulated = np.zeros(len(p), bool)
        simulated[run] = True
        base = int(jax.random.bits(kid, (), jnp.uint32))
        return dict(
            label=label,
            relation=np.asarray(s.relation, np.int32),
            cog_distance=np.asarray(s.cog_distance, np.float32),
            toy=names[p, 0], other=names[p, 1], pair=p.astype(np.int32),
            qpos0=np.asarray(s.qpos0, np.float32), qpos_settled=qpos,
            qpos_final=np.asarray(qpos_final, np.float32),
            rollout_id=np.int64(base) * int(batch_size) + np.arange(int(batch_size), dtype=np.int64),
            intended=np.asarray(s.intended, np.int32), at_rest=np.asarray(s.at_rest, bool),
            feasible=np.asarray(plan.feasible, bool), ik_error=np.asarray(plan.ik_error, np.float32),
            reach_before=np.asarray(before, bool), reach_after=after, simulated=simulated,
        )

    return rollout_fn


# ---------------------------------------------------------------- native MuJoCo C replay


def _both_pads(d: mujoco.MjData, arm: A.Arm, cfg: ActionConfig, geoms: set) -> bool:
    """Do both finger pads touch one of ``geoms`` with their gripping face (C contacts, the
    rule of ``arm.finger_contacts``)?"""
    hit = [False, False]
    for c in d.contact[:d.ncon]:
        if c.dist >= cfg.arm.contact_dist:
            continue
        for i, pad in enumerate(arm.pad_geoms):
            if (c.geom1 == pad and c.geom2 in geoms) or (c.geom2 == pad and c.geom1 in geoms):
                axis = d.geom_xmat[pad].reshape(3, 3)[:, 1]
                if abs(float(np.dot(c.frame[:3], axis))) >= cfg.arm.contact_face_cos:
                    hit[i] = True
    return hit[0] and hit[1]


def replay_native(action: str, cfg: ActionConfig, pair: np.ndarray, qpos: np.ndarray,
                  qvel: np.ndarray, result: dict) -> dict[str, np.ndarray]:
    """Replay the planned programs of an ``action_fn`` result in native MuJoCo C (``mj_step``,
    float64), scene by scene, with the same actuator commands; label them with the same rules.

    Args: pair (B,), qpos (B, 14), qvel (B, 12) settled object states; ``result``: the action
    fn's output for these scenes (uses ``q_way``, ``grip_way``, ``feasible``; directions come
    from a re-plan).
    Returns ``label``, ``com_m``, ``com_end``, ``qpos_final`` as numpy arrays.
    """
    aid = action_id(action)
    st = setup(cfg)
    arm, world = st.arm, st.world
    measure = int(_TPL_MEASURE[aid])
    seg = jnp.asarray(_TPL_STEPS[aid])
    ctrl_fn = jax.jit(jax.vmap(lambda qw, gw, t: A.program_ctrl(arm, qw, gw, seg, t), in_axes=(None, None, 0)))
    reach = jax.jit(lambda p, q: toy_reachable(arm, cfg, st.geo, p, q))
    init = jax.jit(lambda q, v: _initial_data(st, cfg, jnp.int32(aid), q, v))
    plan = jax.jit(make_plan_fn(cfg))(aid, jnp.asarray(pair), jnp.asarray(qpos, jnp.float32))
    labels, com_m, com_end, finals = [], [], [], []
    nqo = qpos.shape[-1]
    wl = welds(world)
    obj_geoms, toy_geoms = set(wl.obj_geoms.tolist()), set(wl.toy_geoms.tolist())
    grasp = int(_GRASPS[aid])
    closed = np.asarray(_TPL_CLOSED[aid])
    segment = np.asarray(A.segment_index(seg, jnp.arange(N_STEPS)))
    for b in range(len(pair)):
        m = world.mj_models[int(pair[b])]
        d = mujoco.MjData(m)
        d0 = init(jnp.asarray(qpos[b], jnp.float32), jnp.asarray(qvel[b], jnp.float32))
        d.qpos[:] = np.concatenate([np.asarray(qpos[b], np.float64), np.asarray(d0.qpos[nqo:], np.float64)])
        d.qvel[:] = 0.0
        d.qvel[:qvel.shape[-1]] = qvel[b]
        d.ctrl[:] = np.asarray(d0.ctrl)
        d.eq_active[:] = np.asarray(d0.eq_active)
        mujoco.mj_forward(m, d)
        com0 = np.stack([d.xipos[world.toy_body], d.xipos[world.obj_body]]).copy()
        ctrl = np.asarray(ctrl_fn(jnp.asarray(result["q_way"][b]), jnp.asarray(result["grip_way"][b]),
                                  jnp.arange(N_STEPS)))
        eq_data0 = m.eq_data.copy()
        cm = None
        for t in range(N_STEPS):
            # the grasp lock of _simulate, on C contacts
            closing = bool(closed[segment[t]])
            for row, body, geoms, kind in ((wl.obj, world.obj_body, obj_geoms, 1),
                                           (wl.toy, world.toy_body, toy_geoms, 2)):
                lock = closing and grasp == kind and (bool(d.eq_active[row]) or _both_pads(d, arm, cfg, geoms))
                if lock and not d.eq_active[row]:
                    m.eq_data[row, 3:10] = np.asarray(A.weld_relpose(
                        jnp.asarray(d.xpos[wl.hand_body]), jnp.asarray(d.xquat[wl.hand_body]),
                        jnp.asarray(d.xpos[body]), jnp.asarray(d.xquat[body])))
                d.eq_active[row] = lock
            d.ctrl[:] = ctrl[t]
            mujoco.mj_step(m, d)
            if t == measure:  # like MJX: the positions of the step's forward pass
                cm = np.stack([d.xipos[world.toy_body], d.xipos[world.obj_body]]).copy()
        ce = np.stack([d.xipos[world.toy_body], d.xipos[world.obj_body]]).copy()
        qf = d.qpos[:nqo].astype(np.float32)
        if aid == _UNOBSTRUCT:
            rb = bool(reach(jnp.asarray(pair[b]), jnp.asarray(qpos[b], jnp.float32)))
            ra = bool(reach(jnp.asarray(pair[b]), jnp.asarray(qf)))
        else:
            rb = ra = False
        o = Outcome(jnp.asarray(com0), jnp.asarray(cm), jnp.asarray(ce), plan.direction[b],
                    jnp.asarray(rb), jnp.asarray(ra))
        m.eq_data[:] = eq_data0
        labels.append(bool(goals(cfg, o)[aid]) and bool(result["feasible"][b]))
        com_m.append(cm)
        com_end.append(ce)
        finals.append(qf)
    return dict(label=np.asarray(labels), com_m=np.stack(com_m), com_end=np.stack(com_end),
                qpos_final=np.stack(finals))


# ------------------------------------------------------------------------------------ CLI


def register_cli(subparsers) -> None:
    """Add ``relaff generate ACTION --samples N --out DIR [--seed S] [--batch B]``."""
    p = subparsers.add_parser(
        "generate",
        help="simulate an action on sampled scenes and write a balanced, resumable dataset",
        description="Sample and settle scenes, run the action in MJX, label by physics, and keep "
        "N samples with 50%% positives (negatives matched to the positives' COG-distance "
        "distribution). Rerun with the same arguments to resume an interrupted run.",
    )
    p.add_argument("action", help=f"one of: {', '.join(ACTIONS)}")
    p.add_argument("--samples", type=int, required=True, help="balanced samples to keep (N >= 2)")
    p.add_argument("--out", required=True, help="dataset directory (new, empty or resumable)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--batch", type=int, default=256, help="scenes per simulated chunk")
    p.add_argument("--max-rollouts", type=int, default=None, help="stop after this many rollouts")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=_cmd_generate)


def _cmd_generate(args) -> int:
    import json
    import sys

    from relaff_jax import config as rc
    from relaff_jax.data import dataset as ds

    if args.action not in ACTIONS:
        print(f"error: unknown action {args.action!r}; valid actions: {', '.join(ACTIONS)}", file=sys.stderr)
        return 2
    if args.samples < 2:
        print(f"error: --samples must be >= 2, got {args.samples}", file=sys.stderr)
        return 2
    if args.batch < 1:
        print(f"error: --batch must be >= 1, got {args.batch}", file=sys.stderr)
        return 2
    cfg = ActionConfig()
    dcfg = ds.DatasetConfig() if args.max_rollouts is None else ds.DatasetConfig(max_rollouts=args.max_rollouts)
    try:
        summary = ds.generate_dataset(
            args.out, args.action, args.samples, make_rollout_fn(args.action, args.batch, cfg),
            args.seed, args.batch, {"action": rc.to_dict(cfg)}, progress=not args.json,
            dataset_config=dcfg)
    except ds.DatasetError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(summary, default=str))
    else:
        print(f"{args.action}: {args.samples} samples written to {args.out} after "
              f"{summary.get('rollouts')} rollouts (positive rate over all rollouts "
              f"{summary.get('positive_rate', float('nan')):.3f})")
    return 0
