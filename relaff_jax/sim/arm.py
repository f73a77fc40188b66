"""The robot arm: names and indices, forward kinematics, inverse kinematics, gripper commands
and motor programs.

Takes a compiled ``mujoco.MjModel`` of any world that includes ``scenes/arm.xml`` (the arm's
MJCF: 6-DOF arm, spherical wrist, two-finger parallel gripper, site ``tcp``) and returns:

- ``Arm``: static name-to-index tables and the kinematic chain constants (plain numpy),
  built once by ``arm_from_model``.
- ``fk_tcp(arm, q)``: tcp pose from the six arm joint angles, a differentiable JAX chain
  (checked against MuJoCo C ``mj_kinematics`` in the tests).
- ``solve_ik(arm, cfg, target, q_init)``: inverse kinematics of one target: projected L-BFGS
  (optax) on the tcp pose error from two seeds (a closed-form geometric guess and the current
  joints); returns the joints, the residuals, the task
  Jacobian's conditioning and a ``reachable`` flag. There is no path planning (paper IV-D): an
  unreachable or badly conditioned target is a failed action, and that failure is data.
- Gripper commands and motor programs: ``program_ctrl`` interpolates joint/gripper waypoints
  into the actuator command at control step ``t``; ``run_program`` executes a program with
  ``lax.scan`` over time on one ``mjx.Data``; ``vmap`` it over scenes at the boundary.
- ``finger_contacts``: whether each finger pad touches given geoms (the grasp test).

Every function here is written for one sample; batch with ``jax.vmap``. The caller owns ``jit``.

Frames: world z up, table plane z = 0, robot at the origin facing +x. The tcp frame has
z = approach direction (out of the palm, between the fingers) and y = finger closing axis.
"""
from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import math
import pathlib
from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import optax

ARM_JOINTS = ("j1", "j2", "j3", "j4", "j5", "j6")
FINGER_JOINTS = ("jf_l", "jf_r")
ARM_ACTUATORS = ("a1", "a2", "a3", "a4", "a5", "a6")
FINGER_ACTUATORS = ("af_l", "af_r")
ARM_BODIES = ("arm_link1", "arm_link2", "arm_link3", "arm_link4", "arm_link5", "arm_hand")
TCP_SITE = "tcp"
PAD_GEOMS = ("arm_pad_l", "arm_pad_r")
PALM_GEOM = "arm_palm"
BASE_BODY = "arm_base"
FINGER_BODIES = ("arm_finger_l", "arm_finger_r")


def scenes_dir() -> pathlib.Path:
    """Directory holding the MJCF files (installed as ``relaff_jax.assets``, else the repo's ``scenes/``)."""
    try:
        path = pathlib.Path(str(importlib.resources.files("relaff_jax.assets")))
        if (path / "arm.xml").exists():
            return path
    except (ModuleNotFoundError, TypeError):  # not installed: running from the repo
        pass
    path = pathlib.Path(__file__).resolve().parents[2] / "scenes"
    if not (path / "arm.xml").exists():
        raise FileNotFoundError(f"arm.xml not found in relaff_jax.assets nor in {path}")
    return path


def arm_xml_path() -> pathlib.Path:
    """Path of ``arm.xml`` (a ``<mujocoinclude>``: include it at a world file's top level)."""
    return scenes_dir() / "arm.xml"


def arm_test_xml_path() -> pathlib.Path:
    """Path of ``arm_test.xml``: table plane + arm + one free 8 cm, 1 kg box named ``obj``."""
    return scenes_dir() / "arm_test.xml"


@dataclasses.dataclass(frozen=True)
class ArmConfig:
    """Static settings of the IK and the gripper (closed over, never traced)."""

    ik_steps: int = 20  # L-BFGS steps per seed
    ik_orient_length: float = 0.25  # m: 1 rad of orientation error weighs like this much position
    ik_pos_tol: float = 0.005  # m: reachable only if the tcp position residual is below
    ik_ang_tol: float = 0.05  # rad (~2.9 deg): and the orientation residual is below
    ik_min_sigma: float = 0.03  # m/rad: and the task Jacobian's smallest singular value above
    ik_continuity: float = 1e-3  # tie-break between good seeds: prefer the one nearest q_init
    grip_open: float = 0.12  # m, default half opening (finger joint value) when open; max 0.21
    grip_closed: float = 0.0  # m, command when closing (force-limited, stops at the object)
    contact_dist: float = 0.002  # m: a pad "touches" a geom if their distance is below
    # ... and only with its inner face: the contact normal within ~45 deg of the closing axis
    # (a pad resting on top of an object, or an edge of it on a rim, is no grip)
    contact_face_cos: float = 0.7


@dataclasses.dataclass(frozen=True, eq=False)
class Arm:
    """Static tables of the arm inside one compiled model (numpy; hashable by identity).

    Index fields address the full model's arrays: ``qpos_arm`` (6,) qpos addresses of j1..j6,
    ``qvel_arm`` (6,), ``qpos_fingers``/``qvel_fingers`` (2,), ``act_arm`` (6,),
    ``act_fingers`` (2,), ``tcp_site``, ``pad_geoms`` (2,), ``palm_geom``, ``hand_body``.
    Chain fields (for ``fk_tcp``): ``base_pos`` (3,), ``base_mat`` (3, 3) world pose of the
    parent of ``arm_link1``; per arm body ``body_pos`` (6, 3), ``body_mat`` (6, 3, 3),
    ``jnt_axis`` (6, 3), ``jnt_pos`` (6, 3) in body coordinates; ``site_pos`` (3,),
    ``site_mat`` (3, 3) of the tcp in the hand frame; joint limits ``q_lo``/``q_hi`` (6,).
    Gripper geometry: ``finger_range`` (2,) half-opening limits, ``tip_below_tcp`` (m, the
    fingertips' distance below the tcp along the approach), ``pad_thickness`` (m, one pad).
    """

    nu: int
    qpos_arm: np.ndarray
    qvel_arm: np.ndarray
    qpos_fingers: np.ndarray
    qvel_fingers: np.ndarray
    act_arm: np.ndarray
    act_fingers: np.ndarray
    tcp_site: int
    pad_geoms: np.ndarray
    palm_geom: int
    hand_body: int
    finger_range: np.ndarray
    base_pos: np.ndarray
    base_mat: np.ndarray
    body_pos: np.ndarray
    body_mat: np.ndarray
    jnt_axis: np.ndarray
    jnt_pos: np.ndarray
    site_pos: np.ndarray
    site_mat: np.ndarray
    q_lo: np.ndarray
    q_hi: np.ndarray
    tip_below_tcp: float
    pad_thickness: float


def _id(model: mujoco.MjModel, objtype: mujoco.mjtObj, name: str) -> int:
    i = mujoco.mj_name2id(model, objtype, name)
    if i < 0:
        kind = mujoco.mjtObj(objtype).name.removeprefix("mjOBJ_").lower()
        raise ValueError(f"model has no {kind} named {name!r}: does it include scenes/arm.xml?")
    return int(i)


def _quat_mat(quat: np.ndarray) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return mat.reshape(3, 3)


def _float32_inside(limit: np.ndarray, direction: int) -> np.ndarray:
    """Joint limits in float32 rounded towards the inside of the range, so a float32 solution
    clipped to them is within the float64 limits of the model too."""
    out = np.asarray(limit, np.float32)
    outside = (out < limit) if direction > 0 else (out > limit)
    return np.where(outside, np.nextafter(out, np.float32(direction * np.inf)), out)


def arm_from_model(model: mujoco.MjModel) -> Arm:
    """Build the ``Arm`` tables from a compiled model that includes ``arm.xml``."""
    J, B, A = mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_ACTUATOR
    G, S = mujoco.mjtObj.mjOBJ_GEOM, mujoco.mjtObj.mjOBJ_SITE
    jids = [_id(model, J, n) for n in ARM_JOINTS]
    fids = [_id(model, J, n) for n in FINGER_JOINTS]
    bids = [_id(model, B, n) for n in ARM_BODIES]
    for n, (j, b) in enumerate(zip(jids, bids)):
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or model.jnt_bodyid[j] != b:
            raise ValueError(f"joint {ARM_JOINTS[n]} must be the hinge of body {ARM_BODIES[n]}")
        if model.body_jntnum[b] != 1:
            raise ValueError(f"body {ARM_BODIES[n]} must have exactly one joint")
        if n and model.body_parentid[b] != bids[n - 1]:
            raise ValueError(f"body {ARM_BODIES[n]} must be the child of {ARM_BODIES[n - 1]}")
    site = _id(model, S, TCP_SITE)
    if model.site_bodyid[site] != bids[-1]:
        raise ValueError(f"site {TCP_SITE!r} must belong to body {ARM_BODIES[-1]}")
    # The chain's root (arm_base) is static: its world pose is fixed at compile time.
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    parent = int(model.body_parentid[bids[0]])
    if model.body_weldid[parent] != 0:
        raise ValueError("the arm's base must be welded to the world (no joints above arm_link1)")
    pad = _id(model, G, PAD_GEOMS[0])
    finger_body = int(model.geom_bodyid[pad])
    tip_z = model.body_pos[finger_body][2] + model.geom_pos[pad][2] - model.geom_size[pad][2]
    return Arm(
        nu=int(model.nu),
        qpos_arm=np.array([model.jnt_qposadr[j] for j in jids]),
        qvel_arm=np.array([model.jnt_dofadr[j] for j in jids]),
        qpos_fingers=np.array([model.jnt_qposadr[j] for j in fids]),
        qvel_fingers=np.array([model.jnt_dofadr[j] for j in fids]),
        act_arm=np.array([_id(model, A, n) for n in ARM_ACTUATORS]),
        act_fingers=np.array([_id(model, A, n) for n in FINGER_ACTUATORS]),
        tcp_site=site,
        pad_geoms=np.array([_id(model, G, n) for n in PAD_GEOMS]),
        palm_geom=_id(model, G, PALM_GEOM),
        hand_body=bids[-1],
        finger_range=np.array(model.jnt_range[fids[0]], dtype=np.float64),
        base_pos=np.array(data.xpos[parent]),
        base_mat=np.array(data.xmat[parent]).reshape(3, 3),
        body_pos=np.array(model.body_pos[bids]),
        body_mat=np.stack([_quat_mat(model.body_quat[b]) for b in bids]),
        jnt_axis=np.array(model.jnt_axis[jids]),
        jnt_pos=np.array(model.jnt_pos[jids]),
        site_pos=np.array(model.site_pos[site]),
        site_mat=_quat_mat(model.site_quat[site]),
        q_lo=_float32_inside(model.jnt_range[jids, 0], +1),
        q_hi=_float32_inside(model.jnt_range[jids, 1], -1),
        tip_below_tcp=float(model.site_pos[site][2] - tip_z),
        pad_thickness=float(2 * model.geom_size[pad][1]),
    )


# ----------------------------------------------------------------------------- kinematics


def _axis_rotation(axis: jax.Array, angle: jax.Array) -> jax.Array:
    """Rodrigues: (3, 3) rotation by ``angle`` about the unit ``axis``."""
    x, y, z = axis[0], axis[1], axis[2]
    k = jnp.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return jnp.eye(3) + jnp.sin(angle) * k + (1.0 - jnp.cos(angle)) * (k @ k)


def fk_chain(arm: Arm, q: jax.Array) -> tuple[jax.Array, jax.Array]:
    """World poses of the six arm bodies: ``q`` (6,) -> pos (6, 3), mat (6, 3, 3).

    Same recursion as MuJoCo's ``mj_kinematics`` for one hinge per body: the body frame is
    placed in its parent, then rotated about the joint axis through the joint anchor.
    """
    pos, mat = jnp.asarray(arm.base_pos), jnp.asarray(arm.base_mat)
    out_pos, out_mat = [], []
    for i in range(6):
        pos = pos + mat @ arm.body_pos[i]
        mat = mat @ arm.body_mat[i]
        anchor = pos + mat @ arm.jnt_pos[i]
        mat = mat @ _axis_rotation(jnp.asarray(arm.jnt_axis[i]), q[i])
        pos = anchor - mat @ arm.jnt_pos[i]
        out_pos.append(pos)
        out_mat.append(mat)
    return jnp.stack(out_pos), jnp.stack(out_mat)


def fk_tcp(arm: Arm, q: jax.Array) -> tuple[jax.Array, jax.Array]:
    """tcp pose in the world: ``q`` (6,) -> pos (3,), mat (3, 3) (columns = tcp x, y, z axes)."""
    pos, mat = fk_chain(arm, q)
    return pos[-1] + mat[-1] @ arm.site_pos, mat[-1] @ arm.site_mat


# ------------------------------------------------------------------------------------ IK


class IKTarget(NamedTuple):
    """A tcp goal. ``pos`` (3,) world position; ``approach`` (3,) unit direction the tcp z must
    point along; ``closing`` (3,) unit direction of the finger closing axis (tcp y);
    ``closing_weight`` () 0 = free yaw about the approach, 1 = closing axis enforced;
    ``closing_signed`` () 0 = the closing axis is sign-free (the gripper is symmetric), 1 = the
    tcp y must point along +closing (a tool attached to the hand is not symmetric)."""

    pos: jax.Array
    approach: jax.Array
    closing: jax.Array
    closing_weight: jax.Array
    closing_signed: jax.Array


class IKResult(NamedTuple):
    """``q`` (6,) joint solution inside the limits; ``pos_err`` () m and ``ang_err`` () rad
    tcp residuals; ``sigma`` () smallest singular value of the task Jacobian (m/rad; small =
    near a singularity); ``reachable`` () bool: all three within the config's tolerances."""

    q: jax.Array
    pos_err: jax.Array
    ang_err: jax.Array
    sigma: jax.Array
    reachable: jax.Array


def top_down_target(pos: jax.Array, yaw: jax.Array | None = None) -> IKTarget:
    """Target with the approach straight down; ``yaw`` (rad, about world z) of the closing
    axis, or ``None`` for a free yaw. ``pos`` (3,)."""
    pos = jnp.asarray(pos, dtype=jnp.float32)
    if yaw is None:
        closing, weight = jnp.array([0.0, 1.0, 0.0]), jnp.asarray(0.0)
    else:
        closing = jnp.stack([jnp.cos(yaw), jnp.sin(yaw), jnp.zeros_like(yaw)])
        weight = jnp.asarray(1.0)
    return IKTarget(pos, jnp.array([0.0, 0.0, -1.0]), closing, weight, jnp.asarray(0.0))


def _residual(arm: Arm, cfg: ArmConfig, q: jax.Array, target: IKTarget) -> jax.Array:
    """(9,) residual: position (m), approach and closing axis errors scaled to metres."""
    pos, mat = fk_tcp(arm, q)
    z, y = mat[:, 2], mat[:, 1]
    free_sign = jnp.where(jnp.dot(y, target.closing) >= 0, 1.0, -1.0)  # symmetric gripper
    sign = jnp.where(target.closing_signed > 0, 1.0, free_sign)
    w = jnp.sqrt(target.closing_weight)
    return jnp.concatenate(
        [pos - target.pos, cfg.ik_orient_length * (z - target.approach),
         cfg.ik_orient_length * w * (y - sign * target.closing)]
    )


def _errors(arm: Arm, q: jax.Array, target: IKTarget) -> tuple[jax.Array, jax.Array]:
    pos, mat = fk_tcp(arm, q)
    pos_err = jnp.linalg.norm(pos - target.pos)
    ang_a = jnp.arccos(jnp.clip(jnp.dot(mat[:, 2], target.approach), -1.0, 1.0))
    dot_c = jnp.dot(mat[:, 1], target.closing)
    dot_c = jnp.where(target.closing_signed > 0, dot_c, jnp.abs(dot_c))
    ang_c = jnp.arccos(jnp.clip(dot_c, -1.0, 1.0))
    return pos_err, jnp.maximum(ang_a, jnp.where(target.closing_weight > 0, ang_c, 0.0))


def task_sigma(arm: Arm, cfg: ArmConfig, q: jax.Array, target: IKTarget) -> jax.Array:
    """Smallest singular value of the constrained task's Jacobian at ``q``.

    The task has 5 dimensions with a free yaw (position + approach direction) and 6 with a
    fixed closing axis; the residual Jacobian (9, 6) has that rank away from singularities.
    """
    jac = jax.jacfwd(lambda qq: _residual(arm, cfg, qq, target))(q)
    s = jnp.linalg.svd(jac, compute_uv=False)  # descending
    return jnp.where(target.closing_weight > 0, s[5], s[4])


def _wrap(angle: jax.Array) -> jax.Array:
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def analytic_seed(arm: Arm, target: IKTarget, q6: jax.Array) -> jax.Array:
    """Geometric first guess for this arm family (yaw, 2-link shoulder/elbow, spherical wrist).

    Used only to start the optimiser; clipped to the limits. ``q6`` () is the tool yaw used
    when the closing axis is free.
    """
    shoulder = arm.base_pos + arm.base_mat @ (arm.body_pos[0] + arm.body_pos[1])
    up, fore = arm.body_pos[2], arm.body_pos[3]  # upper arm (link2 frame), forearm (link3)
    l1, l2 = float(np.linalg.norm(up)), float(np.linalg.norm(fore))
    a_u, a_f = math.atan2(up[0], up[2]), math.atan2(fore[0], fore[2])  # angles from vertical
    reach_tcp = float(np.linalg.norm(arm.site_pos))  # hand origin = wrist centre
    wrist = target.pos - reach_tcp * target.approach
    rel = wrist - shoulder
    j1 = jnp.arctan2(rel[1], rel[0])
    r = jnp.hypot(rel[0], rel[1])
    dist = jnp.clip(jnp.hypot(r, rel[2]), abs(l1 - l2) + 1e-3, l1 + l2 - 1e-4)
    cos_g = (l1 ** 2 + l2 ** 2 - dist ** 2) / (2 * l1 * l2)
    phi = jnp.pi - jnp.arccos(jnp.clip(cos_g, -1.0, 1.0))  # bend between arm directions
    beta = jnp.arctan2(r, rel[2])
    alpha = jnp.arctan2(l2 * jnp.sin(phi), l1 + l2 * jnp.cos(phi))
    j2 = beta - alpha - a_u
    j3 = phi - a_f + a_u
    # wrist: approach in the arm plane's frame -> pitch sum and lateral roll
    c1, s1 = jnp.cos(j1), jnp.sin(j1)
    a = target.approach
    ax, ay, az = c1 * a[0] + s1 * a[1], -s1 * a[0] + c1 * a[1], a[2]
    j5 = jnp.arcsin(jnp.clip(ay, -1.0, 1.0))
    j4 = jnp.arctan2(-ax, -az) - j2 - j3
    q = jnp.stack([j1, j2, j3, j4, j5, jnp.zeros_like(j1)])
    # tool yaw: turn the tcp y axis onto the closing axis (mod pi if the gripper is symmetric)
    _, mat = fk_tcp(arm, q)
    c = mat.T @ target.closing
    turn = jnp.arctan2(c[0], c[1])
    j6 = jnp.where(target.closing_signed > 0, turn, _wrap(2.0 * turn) / 2.0)
    j6 = jnp.where(target.closing_weight > 0, j6, q6)
    q = q.at[5].set(j6)
    return jnp.clip(q, arm.q_lo, arm.q_hi)


def _descend(arm: Arm, cfg: ArmConfig, q0: jax.Array, target: IKTarget) -> jax.Array:
    """L-BFGS (optax, zoom line search) on the squared pose residual from ``q0`` (6,): a fixed
    number of steps under ``lax.scan``, each projected onto the joint limits by clipping."""
    loss = lambda q: jnp.sum(_residual(arm, cfg, q, target) ** 2)
    opt = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(loss)

    def step(carry, _):
        q, state = carry
        value, grad = value_and_grad(q, state=state)
        updates, state = opt.update(grad, state, q, value=value, grad=grad, value_fn=loss)
        q = jnp.clip(optax.apply_updates(q, updates), arm.q_lo, arm.q_hi)
        return (q, state), None

    (q, _), _ = jax.lax.scan(step, (q0, opt.init(q0)), None, length=cfg.ik_steps)
    return q


def solve_ik(arm: Arm, cfg: ArmConfig, target: IKTarget, q_init: jax.Array) -> IKResult:
    """Inverse kinematics of one tcp target (vmap over scenes at the call site).

    ``q_init`` (6,) is the current arm configuration: one seed starts there (continuity along
    a motor program), the other at ``analytic_seed``. Among the seeds that meet the
    tolerances the one nearest ``q_init`` wins, else the one with the smallest error.
    """
    q_init = jnp.clip(jnp.asarray(q_init, jnp.float32), arm.q_lo, arm.q_hi)
    seeds = jnp.stack([analytic_seed(arm, target, q_init[5]), q_init])
    qs = jax.vmap(lambda s: _descend(arm, cfg, s, target))(seeds)
    pos_err, ang_err = jax.vmap(lambda q: _errors(arm, q, target))(qs)
    ok = (pos_err < cfg.ik_pos_tol) & (ang_err < cfg.ik_ang_tol)
    cost = pos_err + cfg.ik_orient_length * ang_err
    cost = cost + cfg.ik_continuity * jnp.sum((qs - q_init) ** 2, axis=-1) + jnp.where(ok, 0.0, 1e3)
    best = jnp.argmin(cost)
    q = qs[best]
    sigma = task_sigma(arm, cfg, q, target)
    reachable = ok[best] & (sigma > cfg.ik_min_sigma)
    return IKResult(q, pos_err[best], ang_err[best], sigma, reachable)


def solve_ik_path(arm: Arm, cfg: ArmConfig, targets: IKTarget, q_init: jax.Array) -> IKResult:
    """IK of a sequence of W targets (leading axis of every ``targets`` field), each warm-started
    from the previous solution so consecutive joint waypoints stay close. Returns ``IKResult``
    with a leading (W,) axis; the program is feasible iff ``reachable.all()``."""

    def step(q_prev, target):
        res = solve_ik(arm, cfg, target, q_prev)
        return res.q, res

    _, res = jax.lax.scan(step, jnp.asarray(q_init, jnp.float32), targets)
    return res


# ------------------------------------------------------------------------ held tools

# Where the tcp holds a tool (the rakes, paper IV-C: "attached to the robot arm as a tool"), in
# the tool's frame: 4 cm along the handle from its near end, on the handle's axis (the rake
# handles are 2.5 cm thick, origin at the bottom); tcp axes in the tool frame: x along the
# handle (+x), closing axis across it (-y), approach down (-z). With this choice the hand's yaw
# joint sits near 0 when the tool points away from the robot.
TOOL_GRIP_POS = np.array([0.04, 0.0, 0.0125])
TOOL_GRIP_MAT = np.diag([1.0, -1.0, -1.0])


def tool_relpose(arm: Arm) -> tuple[np.ndarray, np.ndarray]:
    """Pose (pos (3,), quat (4,)) of a held tool's frame in the hand frame: the ``relpose`` of
    the weld ``arm_hand`` -> tool (MuJoCo: body2's pose in body1's frame)."""
    rot = arm.site_mat @ TOOL_GRIP_MAT.T  # tool axes in the hand frame
    pos = arm.site_pos - rot @ TOOL_GRIP_POS
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.reshape(-1))
    return pos, quat


def tool_tcp_target(tool_pos: jax.Array, tool_mat: jax.Array) -> IKTarget:
    """The (signed) tcp target that puts a held tool's frame at ``tool_pos`` (3,), ``tool_mat``
    (3, 3)."""
    grip_pos, grip_mat = jnp.asarray(TOOL_GRIP_POS), jnp.asarray(TOOL_GRIP_MAT)
    return IKTarget(tool_pos + tool_mat @ grip_pos, tool_mat @ grip_mat[:, 2], tool_mat @ grip_mat[:, 1],
                    jnp.asarray(1.0), jnp.asarray(1.0))


def world_mjcf(tool_body: str | None = None, grasp_bodies: Sequence[str] = ()) -> str:
    """The arm's MJCF sections (default, worldbody, contact, actuator) as text to insert at the
    top level of a world's ``<mujoco>`` element (after its own sections), plus inactive welds
    from the hand, all switched per scene with ``mjx.Data.eq_active``:

    - with ``tool_body``: ``tool_grip``, attaching that body at the tool grip pose
      (``TOOL_GRIP_*``), for a held tool;
    - for each name in ``grasp_bodies``: ``grasp_<name>``, whose relative pose the caller sets
      (``eq_data``) at the moment both finger pads touch that body (a grasp lock).
    """
    text = arm_xml_path().read_text()
    start, end = text.index("<mujocoinclude>"), text.index("</mujocoinclude>")
    body = text[start + len("<mujocoinclude>"):end]
    welds = []
    if tool_body is not None:
        arm = arm_from_model(mujoco.MjModel.from_xml_path(str(arm_test_xml_path())))
        pos, quat = tool_relpose(arm)
        rel = " ".join(f"{v:.9g}" for v in (*pos, *quat))
        welds.append(f'<weld name="tool_grip" body1="arm_hand" body2="{tool_body}" relpose="{rel}" '
                     f'active="false" solref="0.008 1"/>')
    for name in grasp_bodies:
        welds.append(f'<weld name="grasp_{name}" body1="arm_hand" body2="{name}" '
                     f'relpose="0 0 0 1 0 0 0" active="false" solref="0.01 1"/>')
    if welds:
        body += "\n  <equality>\n    " + "\n    ".join(welds) + "\n  </equality>\n"
    return body


# ------------------------------------------------------------------ gripper and programs


def grip_command(cfg: ArmConfig, closed: jax.Array) -> jax.Array:
    """Finger command (half opening, m) for a bool/0..1 ``closed`` (1 = close, force-limited)."""
    closed = jnp.asarray(closed, jnp.float32)
    return cfg.grip_open + (cfg.grip_closed - cfg.grip_open) * closed


def make_ctrl(arm: Arm, q_arm: jax.Array, grip: jax.Array, ctrl: jax.Array | None = None) -> jax.Array:
    """Actuator vector (nu,) with the arm targets ``q_arm`` (6,) and both fingers at ``grip``."""
    ctrl = jnp.zeros(arm.nu) if ctrl is None else ctrl
    ctrl = ctrl.at[arm.act_arm].set(q_arm)
    return ctrl.at[arm.act_fingers].set(grip)


def weld_relpose(xpos1: jax.Array, xquat1: jax.Array, xpos2: jax.Array, xquat2: jax.Array) -> jax.Array:
    """(7,) pose of body 2 in body 1's frame (pos, quat): a weld's ``relpose`` that holds the
    two bodies as they are now (``eq_data[3:10]`` of a weld)."""
    q1 = xquat1 / jnp.linalg.norm(xquat1)
    conj = q1 * jnp.array([1.0, -1.0, -1.0, -1.0])
    w1, v1 = conj[0], conj[1:]
    w2, v2 = xquat2[0], xquat2[1:]
    quat = jnp.concatenate([jnp.array([w1 * w2 - v1 @ v2]), w1 * v2 + w2 * v1 + jnp.cross(v1, v2)])
    rot1 = jnp.array([
        [1 - 2 * (q1[2] ** 2 + q1[3] ** 2), 2 * (q1[1] * q1[2] - q1[0] * q1[3]), 2 * (q1[1] * q1[3] + q1[0] * q1[2])],
        [2 * (q1[1] * q1[2] + q1[0] * q1[3]), 1 - 2 * (q1[1] ** 2 + q1[3] ** 2), 2 * (q1[2] * q1[3] - q1[0] * q1[1])],
        [2 * (q1[1] * q1[3] - q1[0] * q1[2]), 2 * (q1[2] * q1[3] + q1[0] * q1[1]), 1 - 2 * (q1[1] ** 2 + q1[2] ** 2)],
    ])
    return jnp.concatenate([rot1.T @ (xpos2 - xpos1), quat / jnp.linalg.norm(quat)])


def segment_index(seg_steps: Sequence[int] | jax.Array, t: jax.Array) -> jax.Array:
    """Index of the program segment running at control step ``t`` (the last one after the end)."""
    ends = jnp.cumsum(jnp.asarray(seg_steps, jnp.int32))
    return jnp.clip(jnp.searchsorted(ends, t, side="right"), 0, ends.shape[0] - 1)


def _smoothstep(x: jax.Array) -> jax.Array:
    return x * x * (3.0 - 2.0 * x)


def program_ctrl(
    arm: Arm, q_way: jax.Array, grip_way: jax.Array, seg_steps: Sequence[int] | jax.Array, t: jax.Array
) -> jax.Array:
    """Actuator command (nu,) at control step ``t`` of a waypoint program.

    ``q_way`` (W, 6) joint waypoints, ``grip_way`` (W,) finger commands; segment k moves from
    waypoint k to k + 1 in ``seg_steps[k]`` control steps (length W - 1; a static tuple, or a
    traced int array so one compiled program serves programs of different timing) with a
    smoothstep profile (zero velocity at the waypoints, no jerk into the contacts). After the
    last segment the command holds the last waypoint.
    """
    if isinstance(seg_steps, (tuple, list)):
        seg_steps = tuple(int(s) for s in seg_steps)
        if len(seg_steps) != q_way.shape[0] - 1 or min(seg_steps) < 1:
            raise ValueError(f"need W - 1 = {q_way.shape[0] - 1} positive segment lengths, got {seg_steps}")
    seg = jnp.asarray(seg_steps, jnp.int32)
    ends = jnp.cumsum(seg)
    k = segment_index(seg, t)
    frac = jnp.clip((t - (ends[k] - seg[k])) / jnp.maximum(seg[k], 1).astype(jnp.float32), 0.0, 1.0)
    s = _smoothstep(frac)
    q = q_way[k] + s * (q_way[k + 1] - q_way[k])
    g = grip_way[k] + s * (grip_way[k + 1] - grip_way[k])
    return make_ctrl(arm, q, g)


def run_program(
    arm: Arm,
    mx,
    dx,
    q_way: jax.Array,
    grip_way: jax.Array,
    *,
    seg_steps: Sequence[int] | jax.Array,
    n_steps: int | None = None,
    substeps: int = 1,
    observe: Callable | None = None,
):
    """Execute a waypoint program on one scene: ``lax.scan`` over control steps, each holding
    the command for ``substeps`` ``mjx.step`` calls. Control steps: ``n_steps`` if given (needed
    when ``seg_steps`` is a traced array), else sum(seg_steps).

    ``mx`` mjx.Model, ``dx`` mjx.Data (one scene), ``q_way`` (W, 6), ``grip_way`` (W,).
    Returns the final ``dx`` and ``observe(dx)`` stacked over control steps (leading axis T),
    or ``None`` without ``observe``. Bind the static arguments with ``functools.partial`` and
    vmap over scenes: ``jax.vmap(partial(run_program, arm, mx, seg_steps=...))(dx, q_way, grip_way)``.
    """
    from mujoco import mjx

    if n_steps is None:
        if not isinstance(seg_steps, (tuple, list)):
            raise ValueError("n_steps is required when seg_steps is an array")
        n_steps = int(sum(seg_steps))

    def control_step(d, t):
        d = d.replace(ctrl=program_ctrl(arm, q_way, grip_way, seg_steps, t))
        d = jax.lax.fori_loop(0, substeps, lambda _, dd: mjx.step(mx, dd), d)
        return d, (None if observe is None else observe(d))

    return jax.lax.scan(control_step, dx, jnp.arange(int(n_steps)))


def finger_contacts(arm: Arm, cfg: ArmConfig, dx, geoms: Sequence[int] | jax.Array) -> jax.Array:
    """(2,) bool: does the left / right finger pad touch any of ``geoms`` (ids) in ``dx``
    with its gripping face?

    Reads the MJX contact list (one scene); a contact counts when its distance is below
    ``cfg.contact_dist`` and its normal is within ``arccos(cfg.contact_face_cos)`` of the
    pad's closing axis (its local y), so a pad pressing on the top of an object does not
    count. A grasp is a grasp only if both are True.
    """
    geoms = jnp.asarray(geoms).reshape(-1)
    con = dx._impl.contact
    g1, g2 = con.geom[:, 0], con.geom[:, 1]
    near = con.dist < cfg.contact_dist
    is_obj1 = jnp.any(g1[:, None] == geoms[None, :], axis=1)
    is_obj2 = jnp.any(g2[:, None] == geoms[None, :], axis=1)
    normal = con.frame[:, 0, :]  # (ncon, 3)

    def touches(pad):
        axis = dx.geom_xmat[pad][:, 1]
        face = jnp.abs(normal @ axis) >= cfg.contact_face_cos
        hit = ((g1 == pad) & is_obj2) | ((g2 == pad) & is_obj1)
        return jnp.any(hit & near & face)

    return jnp.stack([touches(int(arm.pad_geoms[0])), touches(int(arm.pad_geoms[1]))])


def set_arm_qpos(arm: Arm, qpos: jax.Array, q_arm: jax.Array, grip: jax.Array) -> jax.Array:
    """qpos with the arm joints at ``q_arm`` (6,) and both fingers at ``grip`` (half opening)."""
    qpos = qpos.at[arm.qpos_arm].set(q_arm)
    return qpos.at[arm.qpos_fingers].set(grip)


__all__ = [
    "ARM_JOINTS", "FINGER_JOINTS", "ARM_ACTUATORS", "FINGER_ACTUATORS", "TCP_SITE", "PAD_GEOMS",
    "PALM_GEOM", "Arm", "ArmConfig", "IKTarget", "IKResult", "arm_from_model", "arm_xml_path",
    "arm_test_xml_path", "fk_chain", "fk_tcp", "top_down_target", "solve_ik", "solve_ik_path",
    "task_sigma", "analytic_seed", "grip_command", "make_ctrl", "program_ctrl", "run_program",
    "finger_contacts", "set_arm_qpos", "weld_relpose", "segment_index", "world_mjcf",
    "tool_relpose", "tool_tcp_target",
]
