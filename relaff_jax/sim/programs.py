"""The nine motor programs of Table I: tcp targets from a settled scene, one scene at a time.

Takes the arm tables, an ``ActionConfig``, the pairs' ``Geometry`` (``bodies.geometry``), a
pair index and the settled object ``qpos`` (14,); gives a ``Program``: up to ``N_TARGETS``
tcp targets (``arm.IKTarget``), the pre-grasp opening, a geometric precondition flag and the
action's horizontal direction. ``toy_reachable`` is unobstruct's reachability test. No path
planning (paper IV-D): the targets are solved by the batched IK in ``planning.py``. Pure JAX;
the caller vmaps and jits. Motor programs: docs/actions.md.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import arm as A
from .bodies import (DOWN, Body, Geometry, Grasp, ball_extent, between_pads, bodies, clear_grasp, perp,
                     squeeze_command, squeezed_half, stack_targets, tool_squeeze, top_down, top_down_grasp, unit_xy)
from .geometry import axis_rotation
from .pad_sweep import carry_meets_toy, wall_between_pads
from .sweep import falls_onto_fingers, step_raise, sweep_crosses, sweep_raise, sweep_tops
from .templates import N_TARGETS, ActionConfig, is_v3 as _v3, is_v4

from relaff_jax.constants import ACTIONS


# -------------------------------------------------------------------------- motor programs


class Program(NamedTuple):
    """Per-scene part of a motor program (single scene)."""

    targets: A.IKTarget  # (K,) tcp targets
    opening: jax.Array  # () pre-grasp half opening
    ok: jax.Array  # () bool: geometric preconditions (object fits the gripper, ...)
    direction: jax.Array  # (3,) the action's horizontal direction (move/pull/push/...), or 0
    grip_closed: jax.Array  # () the fingers' command while closing (v2: bounded squeeze)


class Scene(NamedTuple):
    """What a program knows of one settled scene: the two bodies, the other's container
    opening (``Geometry.oth_inner``) and the masses (kg)."""

    toy: Body
    oth: Body
    inner: jax.Array
    toy_mass: jax.Array
    oth_mass: jax.Array
    toy_radius: jax.Array


def _scene(geo: Geometry, pair: jax.Array, qpos: jax.Array) -> Scene:
    toy, oth = bodies(geo, pair, qpos)
    g = lambda a: jnp.asarray(a)[pair]
    return Scene(toy, oth, g(geo.oth_inner), g(geo.toy_mass), g(geo.oth_mass), g(geo.toy_radius))


def tipping_body(toy: Body, radius: jax.Array) -> Body:
    """The toy's box grown upwards to its diagonal: the highest a toy tipping over about a
    bottom edge reaches above its bottom (upright toys; its own frame's z is up). A ball
    (``radius`` > 0) rolls instead: its box as it is."""
    size = toy.hi - toy.lo
    reach = jnp.sqrt(size[2] ** 2 + jnp.maximum(size[0], size[1]) ** 2)
    return toy._replace(hi=toy.hi.at[2].set(jnp.where(radius > 0, toy.hi[2], toy.lo[2] + reach)))


def _base_grasp(arm: A.Arm, cfg: ActionConfig, sc: Scene, tilt: bool = False) -> tuple[Grasp, jax.Array]:
    """The grasp of the other object (base or obstacle) and the closing command: v1 as ever;
    v2 with the palm clear of both objects and a squeeze for both objects' weight. ``tilt``
    (pour, slide; ``cfg.tilt_sweep``): the palm clears the toy's diagonal, since a tilted
    toy may tip over inside or on its base. v3: the squeeze from the body the pads end on
    (``bodies.squeezed_half``), and refused where that is the toy (``toy_spans_pads``). v4: the
    palm also clears the diagonal of a toy the pads push across (``pushed_across``)."""
    g = top_down_grasp(arm, cfg, sc.oth)
    if cfg.programs == "v1":
        return g, jnp.asarray(cfg.arm.grip_closed, jnp.float32)
    toy = tipping_body(sc.toy, sc.toy_radius) if tilt and cfg.tilt_sweep else sc.toy
    g0, g = g, clear_grasp(arm, cfg, g, sc.oth, toy, jnp.zeros(3))
    if is_v4(cfg):  # a toy the pads push across may tip: the palm clears its diagonal too
        tall = clear_grasp(arm, cfg, g0, sc.oth, tipping_body(sc.toy, sc.toy_radius), jnp.zeros(3))
        tall = tall._replace(fits=tall.fits & g.fits)
        g = jax.tree_util.tree_map(lambda a, b: jnp.where(pushed_across(arm, g, sc), a, b), tall, g)
    mass = sc.toy_mass + sc.oth_mass
    half = sc.oth.half_width(g.closing)
    if _v3(cfg):
        g = g._replace(fits=g.fits & ~toy_spans_pads(arm, g, sc))
        half = squeezed_half(arm, g, half, sc.toy, sc.toy_radius)
    return g, squeeze_command(arm, cfg, half, mass)


def toy_spans_pads(arm: A.Arm, g: Grasp, sc: Scene) -> jax.Array:
    """v3: would the pads of the base grasp ``g`` end on the toy instead of the base? They do
    when the toy lies between them (``bodies.between_pads``) and is wider along the closing axis
    than the base: pushed across, it still meets both pads before the base does (a 10 cm toy
    car across a 9 cm cup). The base is then never gripped (the grasp lock needs both pads on
    it), so the program cannot do what it is for: refused at plan time. A narrower toy met
    first by one pad (a ball or car overhanging its base's edge) is pushed across until the
    pads rest on the base, and is grasped as in v2."""
    toy_half = ball_extent(sc.toy, sc.toy_radius)[0](g.closing)
    return between_pads(arm, g, sc.toy, sc.toy_radius) & (toy_half > sc.oth.half_width(g.closing))


def pushed_across(arm: A.Arm, g: Grasp, sc: Scene) -> jax.Array:
    """v4: would the closing pads of the base grasp ``g`` push the toy across the base's top? They
    do when the toy lies between them (``bodies.between_pads``), is no wider than the base along
    the closing axis (else ``toy_spans_pads``) and reaches past the base's side there: the pad on
    that side meets it first and pushes it until the pads rest on the base. Pushed across an open
    container, one end drops into the opening and the other rises (pull 10054 of the paper v3
    dataset: a toy car on a cup, 9 mm over its edge, then under the palm at 2.95 N for 0.55 s),
    so the palm clears the toy's tipping reach (``tipping_body``), as pour's and slide's do."""
    toy_half = ball_extent(sc.toy, sc.toy_radius)[0](g.closing)
    base_half = sc.oth.half_width(g.closing)
    reach = jnp.abs((sc.toy.centre - g.xy) @ g.closing) + toy_half
    return between_pads(arm, g, sc.toy, sc.toy_radius) & (toy_half <= base_half) & (reach > base_half)


def _take_grasp(arm: A.Arm, cfg: ActionConfig, toy: Body) -> Grasp:
    """Take's grasp: top-down at the toy's centre with a fixed pre-grasp opening
    (``cfg.take_opening``) and, unless ``cfg.take_align``, the closing axis across the line
    from the robot, whatever the toy's yaw. A toy wider than the opening along that axis
    meets the pads as they come down; physics decides whether they turn it into the gap or
    miss (the grasp lock needs both pads' faces on the toy). In a container the pads must also fit beside the toy."""
    g = top_down_grasp(arm, cfg, toy)
    if cfg.take_align:
        closing = g.closing
    else:
        closing = perp(unit_xy(toy.centre))
    opening = jnp.asarray(cfg.take_opening, jnp.float32)
    return g._replace(closing=closing, opening=opening, fits=opening <= float(arm.finger_range[1]))


def _toy_grasp(arm: A.Arm, cfg: ActionConfig, sc: Scene) -> tuple[Grasp, jax.Array]:
    """Take's grasp and closing command (v2: palm clear, squeeze for the toy's weight; v3: the
    squeeze from the body the pads end on, ``bodies.squeezed_half``; v4: refused where the pads
    would end on the other object's wall and the toy together, ``pad_sweep.wall_between_pads``)."""
    g = _take_grasp(arm, cfg, sc.toy)
    if cfg.programs == "v1":
        return g, jnp.asarray(cfg.arm.grip_closed, jnp.float32)
    g = clear_grasp(arm, cfg, g, sc.toy, sc.oth, sc.inner)
    half = jnp.where(sc.toy_radius > 0, sc.toy_radius, sc.toy.half_width(g.closing))  # a ball's is its radius
    if _v3(cfg):  # the pads end on the widest body between them: the toy, or a cup around it
        half = squeezed_half(arm, g, half, sc.oth)
    if is_v4(cfg):  # ... and not on a wall that stands between them with the toy
        g = g._replace(fits=g.fits & ~wall_between_pads(arm, g, sc.oth, sc.inner))
    return g, squeeze_command(arm, cfg, half, sc.toy_mass)


def _transit_z(arm: A.Arm, cfg: ActionConfig, toy: Body, oth: Body) -> jax.Array:
    return jnp.maximum(toy.z_range()[1], oth.z_range()[1]) + cfg.clearance + arm.tip_below_tcp


def _program_lift(arm, cfg, sc: Scene, *, grasp_toy: bool, tilt: bool) -> Program:
    toy, oth = sc.toy, sc.oth
    g, squeeze = _toy_grasp(arm, cfg, sc) if grasp_toy else _base_grasp(arm, cfg, sc, tilt)
    up = jnp.maximum(_transit_z(arm, cfg, toy, oth), g.tcp_z + 0.05)
    pos = lambda z: g.xy + jnp.array([0.0, 0.0, 1.0]) * z
    targets = [top_down(pos(up), g.closing), top_down(pos(g.tcp_z), g.closing),
               top_down(pos(g.tcp_z + cfg.lift_height), g.closing)]
    if tilt:
        # tilt about the closing axis: the surface slopes along the pads' faces, so nothing
        # slides into a finger (a finger would act as a wall and keep the toy); lean the tool
        # towards the robot, the side the arm reaches more easily
        rot = axis_rotation(g.closing, jnp.deg2rad(cfg.tilt_deg))
        lean_out = jnp.dot(rot @ DOWN, unit_xy(g.xy)) > 0
        if cfg.programs != "v1" and cfg.tilt_lean == "toy":
            # the base's side under the toy goes down (the surface falls away from the tool's
            # lean), so a sliding or toppling toy leaves the hand instead of passing under the
            # palm; a toy within 1 cm of the grasp along the slope keeps the lean towards the robot
            off = jnp.dot(toy.centre - g.xy, perp(g.closing))
            lean_out = jnp.where(jnp.abs(off) > 0.01, jnp.dot(rot @ DOWN, perp(g.closing)) * off > 0, lean_out)
        rot = jnp.where(lean_out, rot.T, rot)
        targets.append(A.IKTarget(pos(g.tcp_z + cfg.lift_height), rot @ DOWN, rot @ g.closing,
                                  jnp.asarray(1.0), jnp.asarray(0.0)))
    return Program(stack_targets(targets), g.opening, g.fits, jnp.zeros(3), squeeze)


def _program_drag(arm, cfg, sc: Scene, *, direction: jax.Array, distance: float, raise_by: float) -> Program:
    toy, oth = sc.toy, sc.oth
    g, squeeze = _base_grasp(arm, cfg, sc)
    up = jnp.maximum(_transit_z(arm, cfg, toy, oth), g.tcp_z + 0.05)
    z = jnp.array([0.0, 0.0, 1.0])
    end = g.xy + direction * distance
    ok = g.fits
    if is_v4(cfg):  # the pads' way from the grasp to the end stays off a toy standing beside the base
        ok = ok & ~carry_meets_toy(arm, g, oth, toy, end)
    targets = [top_down(g.xy + z * up, g.closing), top_down(g.xy + z * g.tcp_z, g.closing),
               top_down(g.xy + z * (g.tcp_z + raise_by), g.closing),
               top_down(end + z * (g.tcp_z + raise_by), g.closing), top_down(end + z * g.tcp_z, g.closing),
               top_down(end + z * (g.tcp_z + 0.10), g.closing)]
    return Program(stack_targets(targets), g.opening, ok, direction, squeeze)


def exit_distance(p: jax.Array, d: jax.Array, body: Body, margin: float) -> jax.Array:
    """Smallest s >= 0 such that ``p - s * d`` (xy) lies outside the body's footprint
    rectangle grown by ``margin`` (0 if it is outside already). p, d: (3,) horizontal."""
    ax = unit_xy(body.mat[:, 0])
    ay = perp(ax)
    half = jnp.stack([body.half_width(ax), body.half_width(ay)]) + margin
    rel = p - body.centre
    o = jnp.stack([rel @ ax, rel @ ay])  # start in the box frame
    v = -jnp.stack([d @ ax, d @ ay])  # walking direction in the box frame
    safe = jnp.where(jnp.abs(v) > 1e-6, v, 1e-6)
    t_out = jnp.min(jnp.maximum((-half - o) / safe, (half - o) / safe))  # leaves the last slab
    inside = jnp.all(jnp.abs(o) < half)
    return jnp.where(inside, jnp.maximum(t_out, 0.0), 0.0)


def _sweep_ends(arm, cfg, toy, oth, c, d, half) -> tuple[jax.Array, jax.Array]:
    """Move's sweep from start to end (3, xy; z 0) along ``d`` across the toy's place ``c``,
    for the hand's footprint ``half(body)`` (half its extent along ``d`` where it meets that
    body): the start beside the toy, stepped back along the line to free table; the end where
    v1's ends (its start's reach: the pads beside the toy)."""
    reach = toy.half_width(d) + half(toy) + cfg.rake_gap
    finger = half(oth) + cfg.rake_gap  # half the hand's footprint, plus a gap
    start = c - d * reach
    start = start - d * exit_distance(start, d, oth, finger)
    end = c + d * (cfg.move_distance - (toy.half_width(d) + arm.pad_thickness + cfg.rake_gap))
    return start, end


def _program_move(arm, cfg, toy, oth, radius, inner) -> Program:
    """Sweep the toy aside along the table: the closed gripper comes down on free table
    beside the toy, fingertips just above the table, and sweeps across the toy's place to
    ``cfg.move_distance`` beyond that start (further if the start had to step back), at right angles to the line from the toy to the other object (across the
    robot's line of sight if their centres nearly coincide), towards the robot's side.

    The program knows where the toy is, not what it stands on: if the toy's side lies over
    the other object, the descent point moves out along the sweep line until it is over free
    table, and the sweep then meets the other object first. v3 raises the sweep over the tops
    near the palm (``sweep.sweep_raise``); v4 also lifts fingertips that would ride onto a low
    base they cross to above its top (``sweep.step_raise``)."""
    c = toy.centre
    c = jnp.array([c[0], c[1], 0.0])
    towards = oth.centre - toy.centre
    far = jnp.linalg.norm(towards[:2]) > 0.02
    d = perp(jnp.where(far, unit_xy(towards), unit_xy(c)))
    d = jnp.where(jnp.dot(d, c) > 0, -d, d)  # the end nearer the robot
    tcp_z = cfg.tip_clearance + 0.005 + arm.tip_below_tcp  # fingertips 1 cm above the table
    ok = jnp.asarray(True)
    half = lambda b: arm.pad_thickness  # half the closed fingers' footprint along d
    if cfg.programs != "v1":
        # a top within palm_margin of the palm's underside is pinned under the palm's edge: the
        # toy's as the fingers push its foot and it tips (a 12 cm can: 70 N into the table for
        # 1.5 s), or the rim of the container the sweep meets first (the palm rides on a
        # basket's rim, 13-23 N for up to 0.9 s): the hand then sweeps higher, the palm
        # palm_margin above that top. The other object counts when the sweep's start lies over it.
        palm = cfg.tip_clearance + 0.005 + arm.palm_above_tip
        clear = lambda top: jnp.where(jnp.abs(top - palm) < cfg.palm_margin, top + cfg.palm_margin - palm, 0.0)
        gap = arm.pad_thickness + cfg.rake_gap
        over = exit_distance(c - d * (toy.half_width(d) + gap), d, oth, gap) > 0
        if _v3(cfg):
            tops, depth = sweep_tops(cfg, toy, oth, over, radius)
            raise_by = sweep_raise(cfg, palm, tops, depth)
            if is_v4(cfg):  # fingertips that would ride onto a low base they cross pass over it
                tip = cfg.tip_clearance + 0.005 + raise_by
                lift = step_raise(cfg, tip, oth.z_range()[1],
                                  sweep_crosses(arm, *_sweep_ends(arm, cfg, toy, oth, c, d, half), d, oth))
                palm_raise = raise_by + sweep_raise(cfg, palm + raise_by + lift, tops, depth)
                # the fallen-toy refusal answers a raise for the palm; over a step alone the toy
                # slides off upright in front of the fingertips (C replays: 21 cars off plates and lids)
                ok = ~(falls_onto_fingers(cfg, toy, oth, inner, palm_raise + lift) & (palm_raise > 0))
                raise_by = palm_raise + lift
            else:
                ok = ~falls_onto_fingers(cfg, toy, oth, inner, raise_by)
            tcp_z = tcp_z + raise_by
        else:
            tcp_z = tcp_z + jnp.maximum(clear(toy.z_range()[1]), jnp.where(over, clear(oth.z_range()[1]), 0.0))
        # ... and the hand's footprint is the palm's (5 cm) where a body reaches up to the palm
        palm_z = tcp_z - arm.tip_below_tcp + arm.palm_above_tip - cfg.palm_margin
        half = lambda b: jnp.where(b.z_range()[1] > palm_z, float(arm.palm_half[1]), arm.pad_thickness)
    start, end = _sweep_ends(arm, cfg, toy, oth, c, d, half)
    up = _transit_z(arm, cfg, toy, oth)
    z = jnp.array([0.0, 0.0, 1.0])
    targets = [top_down(start + z * up, d), top_down(start + z * tcp_z, d), top_down(end + z * tcp_z, d),
               top_down(end + z * (tcp_z + 0.10), d)]
    return Program(stack_targets(targets), jnp.asarray(0.0), ok, d,
                   jnp.asarray(cfg.arm.grip_closed, jnp.float32))


# m, v3: the closest the held rake's pull may bring the hand (tcp) to the base joint's axis. The
# base turns at the hand's speed over its distance from the axis: at the pull's peak speed
# (0.45 m/s, 30 cm in 1 s with the smoothstep) 10 cm is 4.5 rad/s; the three audited pulls
# that passed the axis ended 7-8 cm from it, the base turning 81-92 degrees while the tool
# pitched 19 degrees and pressed the table at 191-199 N.
RAKE_AXIS_CLEARANCE = 0.10


def axis_distance(arm: A.Arm, a: jax.Array, b: jax.Array) -> jax.Array:
    """() m: the horizontal distance from the base joint's (vertical) axis to the segment from
    ``a`` to ``b`` (3,), a straight tcp move."""
    o = jnp.asarray(arm.base_pos, jnp.float32)[:2]
    a, b = a[:2] - o, b[:2] - o
    ab = b - a
    s = jnp.clip(-jnp.dot(a, ab) / jnp.maximum(jnp.dot(ab, ab), 1e-12), 0.0, 1.0)
    return jnp.linalg.norm(a + s * ab)


def ahead_of_base(arm: A.Arm, p: jax.Array, radial: jax.Array) -> jax.Array:
    """() m: how far the point ``p`` (3,) lies in front of the base joint's axis along the
    horizontal unit direction ``radial`` (3,); negative behind it."""
    o = jnp.asarray(arm.base_pos, jnp.float32)
    return jnp.dot((p - o)[:2], radial[:2])


def _program_rake(arm, cfg, toy, geo_head_x0, geo_head_y) -> Program:
    """Put the rake head behind the toy (seen from the robot), beside the handle, and pull."""
    radial = unit_xy(toy.centre)
    side = perp(radial)
    tool_mat = jnp.stack([radial, side, jnp.array([0.0, 0.0, 1.0])], axis=1)
    # toy centre in the tool frame: in front of the head's near face, beside the handle
    x_t = geo_head_x0 - toy.half_width(radial) - cfg.rake_gap
    handle_half = 0.0125
    y_t = handle_half + cfg.rake_gap + toy.half_width(side)
    c = toy.centre
    origin = jnp.array([c[0], c[1], 0.0]) - radial * x_t - side * y_t
    # the head's bottom 3 mm above the table (v1); v2 also keeps the fingertips, which reach
    # below the handle's underside (tip_below_tcp past the handle's centre line), tip_clearance
    # above it: at 3 mm they were 4.5 mm into the table and levered the rake at 100-275 N
    low_z = 0.003
    if cfg.programs != "v1":
        low_z = max(low_z, arm.tip_below_tcp - float(A.TOOL_GRIP_POS[2]) + cfg.tip_clearance)
    low = origin + jnp.array([0.0, 0.0, low_z])
    above = origin + jnp.array([0.0, 0.0, toy.z_range()[1] + cfg.clearance])
    pulled = low - radial * cfg.rake_pull
    raised = pulled + jnp.array([0.0, 0.0, 0.10])
    targets = [A.tool_tcp_target(p, tool_mat) for p in (above, low, pulled, raised)]
    # the toy must lie within the head's lateral extent to be caught at all
    covers = y_t - toy.half_width(side) < geo_head_y[1]
    if _v3(cfg):  # the hand's pull line clear of the base axis (else the base spins, the tool swings)
        covers = covers & (axis_distance(arm, targets[1].pos, targets[2].pos) >= RAKE_AXIS_CLEARANCE)
        # and the hand in front of the base: a tool toy near the robot puts the grip point behind
        # it, the arm folded back over the base, where the descent leaves its vertical line
        covers = covers & (ahead_of_base(arm, targets[1].pos, radial) >= 0.0)
    return Program(stack_targets(targets), jnp.asarray(0.0), covers, -radial,
                   jnp.asarray(tool_squeeze(arm, cfg), jnp.float32))


def _corridor_blocked(cfg: ActionConfig, toy: Body, obst: Body, min_radius: float) -> jax.Array:
    """Is the straight approach from the robot to the toy blocked by the obstacle?

    The corridor is the segment from the robot (at ``min_radius`` on the line to the toy) to
    the toy's centre, widened by the toy's half width plus ``cfg.corridor``; blocked when the
    obstacle's footprint rectangle comes closer to the segment than that.
    """
    radial = unit_xy(toy.centre)
    c = toy.centre
    p1 = jnp.array([c[0], c[1]])
    p0 = radial[:2] * min_radius
    s = jnp.linspace(0.0, 1.0, 24)[:, None]
    pts = p0 + s * (p1 - p0)
    ax = unit_xy(obst.mat[:, 0])[:2]
    ay = jnp.array([-ax[1], ax[0]])
    oc = obst.centre[:2]
    local = jnp.stack([(pts - oc) @ ax, (pts - oc) @ ay], -1)
    half = jnp.stack([obst.half_width(jnp.array([ax[0], ax[1], 0.0])),
                      obst.half_width(jnp.array([ay[0], ay[1], 0.0]))])
    dist = jnp.linalg.norm(jnp.maximum(jnp.abs(local) - half, 0.0), axis=-1)
    width = toy.half_width(jnp.array([-radial[1], radial[0], 0.0])) + cfg.corridor
    return jnp.min(dist) < width


def toy_grasp_target(arm: A.Arm, cfg: ActionConfig, geo: Geometry, pair: jax.Array,
                     qpos: jax.Array) -> tuple[A.IKTarget, jax.Array]:
    """The tcp target of unobstruct's reachability test (a top-down grasp of the toy) and
    whether its other conditions hold (the toy fits the gripper, the corridor is clear)."""
    toy, obst = bodies(geo, pair, qpos)
    g = top_down_grasp(arm, cfg, toy)
    if cfg.programs != "v1":  # the toy's grasp keeps the palm off the obstacle too
        g = clear_grasp(arm, cfg, g, toy, obst, jnp.zeros(3))
    target = top_down(g.xy + jnp.array([0.0, 0.0, 1.0]) * g.tcp_z, g.closing)
    return target, g.fits & ~_corridor_blocked(cfg, toy, obst, cfg.scene.min_radius)


def toy_reachable(arm: A.Arm, cfg: ActionConfig, geo: Geometry, pair: jax.Array, qpos: jax.Array) -> jax.Array:
    """Unobstruct's reachability of the toy (one scene): a top-down grasp of the toy is
    reachable by the IK **and** the approach corridor from the robot is clear of the obstacle."""
    target, clear = toy_grasp_target(arm, cfg, geo, pair, qpos)
    return A.solve_ik(arm, cfg.arm, target, jnp.zeros(6)).reachable & clear


def program(action: str, arm: A.Arm, cfg: ActionConfig, geo: Geometry, pair: jax.Array,
            qpos: jax.Array) -> Program:
    """The per-scene motor program of ``action`` from the settled ``qpos`` (nq,) (one scene);
    its targets padded to ``N_TARGETS`` by repeating the last one."""
    sc = _scene(geo, pair, qpos)
    toy, oth = sc.toy, sc.oth
    if action in ("lift", "take", "pour", "slide"):
        prog = _program_lift(arm, cfg, sc, grasp_toy=action == "take",
                             tilt=action in ("pour", "slide"))
    elif action in ("pull", "push"):
        radial = unit_xy(oth.centre)
        sign = -1.0 if action == "pull" else 1.0
        dist = cfg.pull_distance if action == "pull" else cfg.push_distance
        prog = _program_drag(arm, cfg, sc, direction=sign * radial, distance=dist,
                             raise_by=cfg.drag_raise)
    elif action == "unobstruct":
        side = perp(unit_xy(toy.centre))
        d = jnp.where(jnp.dot(oth.centre, side) >= jnp.dot(toy.centre, side), 1.0, -1.0) * side
        prog = _program_drag(arm, cfg, sc, direction=d, distance=cfg.unobstruct_distance,
                             raise_by=cfg.drag_raise + 0.01)
    elif action == "move":
        prog = _program_move(arm, cfg, toy, oth, sc.toy_radius, sc.inner)
    elif action == "rake":
        prog = _program_rake(arm, cfg, toy, jnp.asarray(geo.head_x0)[pair], jnp.asarray(geo.head_y)[pair])
    else:
        raise ValueError(f"unknown action {action!r}; valid actions: {', '.join(ACTIONS)}")
    k = prog.targets.pos.shape[0]
    pad = lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], N_TARGETS - k, axis=0)])
    return prog._replace(targets=jax.tree_util.tree_map(pad, prog.targets))
