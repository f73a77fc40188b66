"""The arm inside a compiled MuJoCo model: names and static index/chain tables.

Takes a compiled ``mujoco.MjModel`` of any world that includes ``scenes/arm.xml`` (the arm's
MJCF: 6-DOF arm, spherical wrist, two-finger parallel gripper, site ``tcp``); gives ``Arm``,
plain numpy tables built once by ``arm_from_model`` (the IK's and gripper's settings are
``config.action.ArmConfig``). Also the paths of the arm's MJCF files.

Frames: world z up, table plane z = 0, robot at the origin facing +x. The tcp frame has
z = approach direction (out of the palm, between the fingers) and y = finger closing axis.
"""
from __future__ import annotations

import dataclasses
import importlib.resources
import pathlib

import mujoco
import numpy as np

from .geometry import quat_to_mat

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
    fingertips' distance below the tcp along the approach), ``pad_thickness`` (m, one pad),
    ``pad_half_x`` (m, a pad's half width across the closing axis), ``palm_above_tip`` (m, the
    palm's underside above the fingertips: the most of an object the pads can reach around),
    ``palm_half`` (2,) the palm's half extents (across, along the closing axis),
    ``finger_kp`` (N/m, the finger servos' gain), ``pad_friction`` (the pads' sliding friction).
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
    pad_half_x: float
    palm_above_tip: float
    palm_half: np.ndarray
    finger_kp: float
    pad_friction: float


def _id(model: mujoco.MjModel, objtype: mujoco.mjtObj, name: str) -> int:
    i = mujoco.mj_name2id(model, objtype, name)
    if i < 0:
        kind = mujoco.mjtObj(objtype).name.removeprefix("mjOBJ_").lower()
        raise ValueError(f"model has no {kind} named {name!r}: does it include scenes/arm.xml?")
    return int(i)


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
    palm = _id(model, G, PALM_GEOM)
    if model.geom_bodyid[palm] != bids[-1] or model.body_pos[finger_body][2] >= 0 or model.geom_quat[palm][0] != 1:
        raise ValueError("the palm must be an unrotated geom of the hand, above the fingers")
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
        body_mat=np.stack([quat_to_mat(np.asarray(model.body_quat[b], np.float64), np) for b in bids]),
        jnt_axis=np.array(model.jnt_axis[jids]),
        jnt_pos=np.array(model.jnt_pos[jids]),
        site_pos=np.array(model.site_pos[site]),
        site_mat=quat_to_mat(np.asarray(model.site_quat[site], np.float64), np),
        q_lo=_float32_inside(model.jnt_range[jids, 0], +1),
        q_hi=_float32_inside(model.jnt_range[jids, 1], -1),
        tip_below_tcp=float(model.site_pos[site][2] - tip_z),
        pad_thickness=float(2 * model.geom_size[pad][1]),
        pad_half_x=float(model.geom_size[pad][0]),
        palm_above_tip=float(model.geom_pos[palm][2] - model.geom_size[palm][2] - tip_z),
        palm_half=np.array(model.geom_size[palm][:2], dtype=np.float64),
        finger_kp=float(model.actuator_gainprm[_id(model, A, FINGER_ACTUATORS[0])][0]),
        pad_friction=float(model.geom_friction[pad][0]),
    )
