"""The robot arm: one import for its tables, kinematics, held tools, gripper commands and
motor-program control.

Takes a compiled ``mujoco.MjModel`` of any world that includes ``scenes/arm.xml``; the pieces:

- ``arm_model``: names, the ``Arm`` tables (``arm_from_model``), MJCF paths;
- ``kinematics``: ``fk_chain``/``fk_tcp`` and the IK (``IKTarget``, ``solve_ik``,
  ``solve_ik_path``); both re-exported here, so ``arm.solve_ik`` etc. keep working;
- here: held tools (``tool_relpose``, ``tool_tcp_target``), the arm's MJCF sections for a
  world (``world_mjcf``), gripper commands, motor programs (``program_ctrl`` interpolates
  joint/gripper waypoints into the actuator command at control step ``t``; ``run_program``
  executes a program with ``lax.scan`` over time on one ``mjx.Data``; ``vmap`` it over scenes
  at the boundary), and ``finger_contacts``: whether each finger pad touches given geoms (the
  grasp test).

Every function here is written for one sample; batch with ``jax.vmap``. The caller owns ``jit``.

Frames: world z up, table plane z = 0, robot at the origin facing +x. The tcp frame has
z = approach direction (out of the palm, between the fingers) and y = finger closing axis.
"""
from __future__ import annotations

from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from .arm_model import (  # noqa: F401 (re-exported)
    ARM_ACTUATORS, ARM_BODIES, ARM_JOINTS, BASE_BODY, FINGER_ACTUATORS, FINGER_BODIES,
    FINGER_JOINTS, PAD_GEOMS, PALM_GEOM, TCP_SITE, Arm, arm_from_model, arm_test_xml_path,
    arm_xml_path, scenes_dir,
)
from .contacts import contacts
from .straight import ctrl_q
from relaff_jax.config.action import ArmConfig
from .kinematics import (  # noqa: F401 (re-exported)
    IKResult, IKTarget, analytic_seed, fk_chain, fk_tcp, solve_ik, solve_ik_path, task_sigma,
    top_down_target,
)


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


def world_mjcf(tool_body: str | None = None, grasp_bodies: Sequence[str] = (), palm_attrs: str = "") -> str:
    """The arm's MJCF sections (default, worldbody, contact, actuator) as text to insert at the
    top level of a world's ``<mujoco>`` element (after its own sections), plus inactive welds
    from the hand, all switched per scene with ``mjx.Data.eq_active``:

    - with ``tool_body``: ``tool_grip``, attaching that body at the tool grip pose
      (``TOOL_GRIP_*``), for a held tool;
    - for each name in ``grasp_bodies``: ``grasp_<name>``, whose relative pose the caller sets
      (``eq_data``) at the moment both finger pads touch that body (a grasp lock).

    ``palm_attrs`` (MJCF attributes, e.g. ``'priority="1" condim="1"'``) are added to the palm
    geom (``PhysicsConfig.arm_palm_objects``).
    """
    text = arm_xml_path().read_text()
    if palm_attrs:
        tag = f'name="{PALM_GEOM}" class="arm_collide"'
        if text.count(tag) != 1:
            raise RuntimeError(f"{arm_xml_path()}: expected one palm geom tag {tag!r}")
        text = text.replace(tag, f"{tag} {palm_attrs}")
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
    arm: Arm, q_way: jax.Array, grip_way: jax.Array, seg_steps: Sequence[int] | jax.Array, t: jax.Array,
    corr: jax.Array | None = None,
) -> jax.Array:
    """Actuator command (nu,) at control step ``t`` of a waypoint program.

    ``q_way`` (W, 6) joint waypoints, ``grip_way`` (W,) finger commands; segment k moves from
    waypoint k to k + 1 in ``seg_steps[k]`` control steps (length W - 1; a static tuple, or a
    traced int array so one compiled program serves programs of different timing) with a
    smoothstep profile (zero velocity at the waypoints, no jerk into the contacts). After the
    last segment the command holds the last waypoint. ``corr`` (W - 1, P - 1, 6) (programs v2,
    ``straight.corrections``): joint corrections that keep the tcp on the straight line of a
    segment; ``None`` (v1): the joints are linear in the fraction, as ever.
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
    if corr is None:
        q = q_way[k] + s * (q_way[k + 1] - q_way[k])
    else:
        q = ctrl_q(q_way[k], q_way[k + 1], corr[k], s)
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
    con = contacts(dx)
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
    "PALM_GEOM", "Arm", "IKTarget", "IKResult", "arm_from_model", "arm_xml_path",
    "arm_test_xml_path", "fk_chain", "fk_tcp", "top_down_target", "solve_ik", "solve_ik_path",
    "task_sigma", "analytic_seed", "grip_command", "make_ctrl", "program_ctrl", "run_program",
    "finger_contacts", "set_arm_qpos", "weld_relpose", "segment_index", "world_mjcf",
    "tool_relpose", "tool_tcp_target",
]
