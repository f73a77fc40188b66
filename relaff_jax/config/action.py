"""The simulation's settings: ``PhysicsConfig`` (the MJX world), ``SceneConfig`` (scene sampling
and settling), ``ArmConfig`` (IK and gripper) and ``ActionConfig`` (motor programs and outcome
rules, the three others nested inside): the tree's ``action`` node. Lengths in metres."""
from __future__ import annotations

import dataclasses
import math

from relaff_jax.config.constraints import (FRACTION, AnyOf, Boolean, Check, Interval, Options, Rule, Seq,
                                           count, length)
from relaff_jax.config.node import Node

# ActionConfig.programs: the motor programs' versions (v1: the first; v2: grasps that fit the
# object, bounded squeeze, goals read at rest; v3: v2 with move's sweep raised to a fixed point
# and base grasps refused that would press the toy too hard; v4, the default: v3 with the arm at
# rest before each descent, the pads' and palm's rules of docs/actions.md "Programs v4" and a
# stillness check of the settled scene)
PROGRAMS = ("v1", "v2", "v3", "v4")
# ActionConfig fields only v2, v3 and v4 read; a v1 dataset's sidecar leaves them out (templates.stored_config)
V2_FIELDS = ("palm_margin", "min_grip", "squeeze_min", "squeeze_max", "squeeze_safety", "rest_hold", "rest_window",
             "guard_depth", "tilt_lean", "tilt_sweep", "straight_pieces")

# PhysicsConfig.arm_palm_objects -> the palm geom's extra MJCF attributes
PALM_MODES = {"contact": "", "frictionless": 'priority="1" condim="1"', "exclude_other": ""}
IK_SOLVERS = ("lbfgs", "lm")  # kinematics.IK_SOLVERS
MAX_GRIP = 0.21  # m: the finger joint's range
MAX_SQUEEZE = 60.0  # N: the finger actuator's limit
STEPS = count(1, 1_000_000)  # control/solver steps: a bound far past any run's


@dataclasses.dataclass(frozen=True)
class PhysicsConfig(Node):
    """Static physics settings shared by settle and action rollouts.

    ``iterations``/``ls_iterations`` cap the constraint solver: uncapped defaults cost ~3x
    (docs/facts.md, "Solver cap") for no visible difference in resting contacts.
    """

    timestep: float = 0.004
    iterations: int = 4
    ls_iterations: int = 6
    solver: str = "Newton"
    table_friction: float = 0.8
    rolling_friction: float = 0.005  # the ball's contacts (condim 6), so it comes to rest
    # The rake is held by the gripper: during settling it stays at this pose (x, y, z of
    # the grip point; handle along +x), above the robot, away from any toy.
    held_rake_pos: tuple[float, float, float] = (0.20, 0.0, 0.55)
    # Let every container wall touch the table (off: they stand on the base plate's
    # footprint and never need to; on costs 12 more contact slots, kept for A/B benchmarks).
    wall_table_contacts: bool = False
    # The arm world only (the settle world has no arm; docs/actions.md, "Tuning"):
    # MJX's broad phase keeps, per collision function, the k geom pairs whose bounding spheres
    # are nearest (MJX's `max_geom_pairs`; -1: all 46 non-plane pairs through the narrow
    # phase). MuJoCo C ignores it. 6, not 4: a take inside a container touches up to 6 of the
    # pads' 12 pairs, and 4 lost 8 of 297 takes (docs/actions.md, "Tuning").
    arm_max_geom_pairs: int = 6
    # Objects are placed >= SceneConfig.min_radius (0.2 m) plus their radius from the robot,
    # outside the 0.09 m pedestal; only a pull or rake from the innermost placements could
    # carry one back to it (off: 7 pairs fewer; labels checked in docs/actions.md, "Tuning").
    arm_pedestal_contacts: bool = False
    # The palm against the other object (`obj`): "contact" (every pair, condim 3);
    # "exclude_other" (no palm-obj pairs; rejected at 2,112 scenes per action: unobstruct's
    # positives rose from 303 to 484 of 969 feasible); "frictionless" (priority 1, condim 1:
    # normal forces only, its pairs in a collision function of their own). With "contact" the
    # palm's 5 pairs with the other join the objects' box-box function (11 pairs), and under
    # the cap they can push a toy-wall contact out of it: a toy left a tilted baking pan
    # (docs/actions.md, "Tuning").
    arm_palm_objects: str = "contact"

    _path = "action.phys"
    _constraints = {
        "timestep": Interval(float, 0.0, 0.1, closed="right"),
        "iterations": count(1, 10_000),
        "ls_iterations": count(1, 10_000),
        "solver": Options(("Newton", "CG")),  # the solvers MJX has
        "table_friction": Interval(float, 0.0, 10.0),
        "rolling_friction": Interval(float, 0.0, 1.0),
        "held_rake_pos": Seq(Interval(float, -10.0, 10.0), length=3),
        "wall_table_contacts": Boolean(),
        "arm_max_geom_pairs": AnyOf(Interval(int, -1, -1), count(1, 10_000)),  # -1: all pairs
        "arm_pedestal_contacts": Boolean(),
        "arm_palm_objects": Options(PALM_MODES),
    }


def _gap() -> Seq:
    return Seq(length(), length=2, increasing=True)  # (lo, hi) with 0 <= lo < hi


@dataclasses.dataclass(frozen=True)
class SceneConfig(Node):
    """Static scene-distribution and settling settings (paper defaults where it gives them)."""

    workspace_radius: float = 1.8
    min_radius: float = 0.2
    p_stacked: float = 0.5  # toy+base scenes that drop the toy onto / into the base
    p_near: float = 0.5  # beside scenes with the toy near the base rather than anywhere
    near_gap: tuple[float, float] = (0.02, 0.30)
    p_between: float = 0.7  # toy+obstacle scenes with the obstacle in the robot's way
    between_gap: tuple[float, float] = (0.01, 0.10)
    drop_height: float = 0.004  # toys start this far above their support
    settle_steps: int = 250  # 1 s at the default 4 ms step
    rest_speed: float = 0.02  # m/s: a body slower than this at the end is "at rest"
    contact_dist: float = 0.002  # m: a contact closer than this is touching
    candidates: int = 16  # rejection-sampling draws per placement (static shapes)
    # The objects scenes are made of (docs/objects.md): names among the 29 built-ins and the
    # library file's objects (empty: all of them), and a library file (.toml or .json, "" none)
    # whose objects join the built-ins. Read and checked with the whole tree (config.tree.check_tree).
    objects: tuple[str, ...] = ()
    library: str = ""

    _path = "action.scene"
    _constraints = {
        "workspace_radius": Interval(float, 0.0, 10.0, closed="right"),
        "min_radius": length(),
        "p_stacked": FRACTION, "p_near": FRACTION, "p_between": FRACTION,
        "near_gap": _gap(), "between_gap": _gap(),
        "drop_height": length(1.0),
        "settle_steps": STEPS,
        "rest_speed": Interval(float, 0.0, 10.0, closed="right"),
        "contact_dist": Interval(float, 0.0, 1.0, closed="right"),
        "candidates": count(1, 4096),
        # names (docs/objects.md); the library file itself is read and checked with the whole tree
        "objects": Seq(Check(lambda v: isinstance(v, str) and v != "", "an object name"), min_len=0, distinct=True),
        "library": Check(lambda v: isinstance(v, str), "a file path (.toml or .json), or \"\" for none"),
        ("min_radius", "workspace_radius"): Rule(
            lambda c: c.min_radius < c.workspace_radius,
            lambda c: f"must be below workspace_radius = {c.workspace_radius}, got {c.min_radius}"),
    }


@dataclasses.dataclass(frozen=True)
class ArmConfig(Node):
    """Static settings of the IK and the gripper (closed over, never traced)."""

    ik_steps: int = 20  # L-BFGS steps per seed
    # "lbfgs" (the default: optax L-BFGS, zoom line search, ``ik_steps`` steps) or "lm"
    # (Levenberg-Marquardt, ``ik_lm_steps`` steps, ``ik_lm.py``; other plans, ~10x faster)
    ik_solver: str = "lbfgs"
    ik_lm_steps: int = 12  # LM steps per seed (ik_solver="lm")
    ik_orient_length: float = 0.25  # m: 1 rad of orientation error weighs like this much position
    ik_pos_tol: float = 0.005  # m: reachable only if the tcp position residual is below
    ik_ang_tol: float = 0.05  # rad (~2.9 deg): and the orientation residual is below
    ik_min_sigma: float = 0.03  # m/rad: and the task Jacobian's smallest singular value above
    ik_continuity: float = 1e-3  # tie-break between good seeds: prefer the one nearest q_init
    # skip the IK of programs whose targets are provably beyond the arm's reach (reach_screen.py):
    # the same plans, feasibility and labels; their ``ik_error`` is NaN (not solved)
    reach_screen: bool = True
    grip_open: float = 0.12  # m, default half opening (finger joint value) when open; max 0.21
    grip_closed: float = 0.0  # m, command when closing (force-limited, stops at the object)
    contact_dist: float = 0.002  # m: a pad "touches" a geom if their distance is below
    # ... and only with its inner face: the contact normal within ~45 deg of the closing axis
    # (a pad resting on top of an object, or an edge of it on a rim, is no grip)
    contact_face_cos: float = 0.7

    _path = "action.arm"
    _constraints = {
        "ik_steps": count(1, 100_000),
        "ik_solver": Options(IK_SOLVERS),
        "ik_lm_steps": count(1, 100_000),
        "ik_orient_length": Interval(float, 0.0, 10.0, closed="right"),
        "ik_pos_tol": Interval(float, 0.0, 1.0, closed="right"),
        "ik_ang_tol": Interval(float, 0.0, math.pi, closed="right"),
        "ik_min_sigma": Interval(float, 0.0, 10.0),
        "ik_continuity": Interval(float, 0.0, 1e6),
        "reach_screen": Boolean(),
        "grip_open": Interval(float, 0.0, MAX_GRIP),
        "grip_closed": Interval(float, 0.0, MAX_GRIP),
        "contact_dist": Interval(float, 0.0, 1.0, closed="right"),
        "contact_face_cos": Interval(float, -1.0, 1.0),
        ("grip_open", "grip_closed"): Rule(
            lambda c: c.grip_closed <= c.grip_open,
            lambda c: f"must be in [grip_closed = {c.grip_closed}, {MAX_GRIP}] (the finger joint's range), "
                      f"got {c.grip_open}"),
    }


_LENGTHS = ("lift_height", "drag_raise", "pull_distance", "push_distance", "unobstruct_distance",
            "move_distance", "rake_pull", "clearance", "grip_margin", "tip_clearance", "rake_gap",
            "lifted", "moved", "closer", "farther", "aside", "take_opening", "corridor", "palm_margin", "min_grip")


@dataclasses.dataclass(frozen=True)
class ActionConfig(Node):
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
    # Simulate each action only to the end of its own program (its measuring step), not
    # through the padding to N_STEPS: lift/take stop after 560 of 815 steps. The labels of
    # lift, take, pour and slide read the measuring step only, so they cannot change; the
    # other actions read the end, now the program's end (docs/actions.md, "Tuning").
    stop_at_program_end: bool = True
    # Which motor programs (docs/actions.md, "Programs v1 and v2", "Programs v3", "Programs v4"):
    # "v4" (the default) is v3 with the arm at rest at the pre-grasp pose before it descends,
    # the pads' footprint grown by the arm's tracking error, the palm clear of the tipping reach
    # of a toy a base grasp pushes across, take's pads kept off a container's wall, a drag's pads
    # kept off a toy in their way, the held rake's slower swing, move's fingertips over a low
    # base, and no program on a scene that does not stay still after settling; "v3" is v2 with
    # move's sweep raised over every top and rim, a base or obstacle grasp refused
    # where the pads would press the toy beyond the force bound, the squeeze commanded from the
    # widest body between the pads, and rake on one IK branch with its turn, axis and hand-ahead
    # refusals and a dwell before the descent; "v2" grasps below an object's top by at most what
    # the pads allow, refuses a grasp that would put the palm on an object, squeezes with a force
    # from the held objects' weight, and reads every goal once the objects are at rest; "v1" the
    # first programs, bit for bit. v1, v2 and v3 stay one --set away to compare labels.
    programs: str = "v4"
    palm_margin: float = 0.02  # v2: the palm's underside this far above every object under it
    min_grip: float = 0.02  # v2: the pads overlap the grasped object by at least this height
    squeeze_min: float = 5.0  # N, v2: the least squeeze per pad
    squeeze_max: float = 20.0  # N, v2: the most squeeze per pad (the actuator's limit is 60 N)
    squeeze_safety: float = 3.0  # v2: squeeze = safety x the held weight / (2 pads x friction)
    rest_hold: int = 200  # v2: control steps the goal may wait for the objects to come to rest
    rest_window: int = 10  # control steps both objects must stay below scene.rest_speed
    guard_depth: float = 0.0  # m, v2: a pad landing on an object (a contact off its gripping
    # face) this deep stops the descent to a grasp where it is (sim/guard.py)
    tilt_lean: str = "toy"  # v2, pour/slide: "toy" tips the base's side the toy stands on down, so a
    # sliding toy leaves the hand; "robot" leans the tool towards the robot as v1 does (a toy
    # on the near side then slides under the palm)
    tilt_sweep: bool = True  # v2, pour/slide: the palm also clears the toy's diagonal, the height
    # a toy tipping over in or on its base reaches (False: its height, as the other programs)
    straight_pieces: int = 8  # v2: a tcp move between two poses of the same orientation follows the
    # straight line, corrected at this many pieces (sim/straight.py); 1: linear in the joints (it sags)
    arm: ArmConfig = ArmConfig()
    phys: PhysicsConfig = PhysicsConfig()
    scene: SceneConfig = SceneConfig()

    _path = "action"
    _constraints = {
        **{k: length(5.0) for k in _LENGTHS},
        "tilt_deg": Interval(float, 0.0, 180.0, closed="neither"),
        "move_rule": Options(("apart", "both")),
        "take_align": Boolean(),
        "stop_at_program_end": Boolean(),
        "programs": Options(PROGRAMS),
        "squeeze_min": Interval(float, 0.0, MAX_SQUEEZE, closed="right"),
        "squeeze_max": Interval(float, 0.0, MAX_SQUEEZE, closed="right"),
        "squeeze_safety": Interval(float, 0.0, 1000.0, closed="right"),
        "rest_hold": count(0, 1_000_000),
        "rest_window": STEPS,
        "tilt_lean": Options(("toy", "robot")),
        "tilt_sweep": Boolean(),
        "straight_pieces": count(1, 64),
        "guard_depth": length(1.0),  # 1 m: no contact is that deep, the guard never stops
        ("squeeze_min", "squeeze_max"): Rule(
            lambda c: c.squeeze_min <= c.squeeze_max,
            lambda c: f"must be in (0, squeeze_max = {c.squeeze_max}] N, got {c.squeeze_min}"),
    }
