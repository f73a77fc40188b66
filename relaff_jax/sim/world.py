"""The world model: one MJX model structure for every object pair.

Takes the object library (``objects.py``); gives a static ``World``: the 124 per-pair
``mujoco.MjModel`` (compiled by MuJoCo C, so inertias, bounding radii and boxes follow the
sizes exactly), and one ``mjx.Model`` whose pair-dependent fields carry a leading
``(P,)`` pair axis. ``scene_models(world, pair)`` gathers a ``(B,)`` batch of models for
``jax.vmap(mjx.step, in_axes=(world.model_axes, 0))``: every scene of every pair runs in
one compiled program (mujoco_playground's domain-randomisation pattern).

Model layout (body order is fixed):
  world: ``table`` plane (the table top is z = 0, the robot base sits at the origin)
  ``toy``: free joint, geoms ``toy_sphere`` (sphere), ``toy_box`` (box)
  ``obj``: free joint, geoms ``obj_base``, ``obj_wall_xp``, ``obj_wall_xn``,
           ``obj_wall_yp``, ``obj_wall_yn`` (boxes)
  optionally the arm of ``scenes/arm.xml`` (added by the action stage).
"""
from __future__ import annotations

import dataclasses
import functools
import threading
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from . import objects as lib

# Segment labels the camera reports per geom (colour segmentation stand-in).
from relaff_jax.constants import SEG_BACKGROUND, SEG_HIDDEN, SEG_OTHER, SEG_TOY  # noqa: F401
from relaff_jax.errors import UserError
from relaff_jax.config.action import PALM_MODES, PhysicsConfig
from .arm import world_mjcf


def _box_geom(name: str, size, pos, mass: float, rgba, extra: str = "") -> str:
    hs = " ".join(f"{s / 2:.6g}" for s in size)
    p = " ".join(f"{v:.6g}" for v in pos)
    c = " ".join(f"{v:.4g}" for v in rgba)
    return (f'<geom name="{name}" type="box" size="{hs}" pos="{p}" mass="{mass:.6g}" '
            f'rgba="{c}" {extra}/>')


def _collapsed(centre) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    c = lib.COLLAPSED * 2
    return (c, c, c), centre


def _toy_geoms(spec: lib.ObjectSpec, phys: PhysicsConfig) -> str:
    rgba = (*spec.colour, 1.0)
    fr = (f'friction="{spec.friction} 0.005 {phys.rolling_friction}" '
          'contype="3" conaffinity="3"')
    if spec.sphere_radius:
        r = spec.sphere_radius
        sphere = (f'<geom name="toy_sphere" type="sphere" size="{r:.6g}" pos="0 0 {r:.6g}" '
                  f'mass="{spec.mass:.6g}" rgba="{" ".join(map(str, rgba))}" condim="6" {fr}/>')
        size, pos = _collapsed((0.0, 0.0, r))
        box = _box_geom("toy_box", size, pos, 1e-6, rgba, fr)
    else:
        # As a toy the cup is a closed, cup-sized block (nothing goes into the toy).
        sx, sy, sz = spec.extent
        box = _box_geom("toy_box", (sx, sy, sz), (0.0, 0.0, sz / 2), spec.mass, rgba, fr)
        sphere = (f'<geom name="toy_sphere" type="sphere" size="{lib.COLLAPSED}" '
                  f'pos="0 0 {sz / 2:.6g}" mass="1e-6" rgba="{" ".join(map(str, rgba))}" '
                  f'condim="6" {fr}/>')
    return sphere + "\n" + box


# Collision bits: 1 = table, 2 = objects (and the arm). Three container walls skip the
# table (12 of the 50 contact slots; settling ran ~3x faster with identical relations on 256
# mixed scenes). wall_xp is also a rake's head, which must meet the table.
_NO_TABLE = ("wall_xn", "wall_yp", "wall_yn")


def _other_geoms(spec: lib.ObjectSpec, phys: PhysicsConfig) -> str:
    rgba = (*spec.colour, 1.0)
    parts = dict(spec.parts)
    vol = {k: float(np.prod(b.size)) for k, b in parts.items()}
    total = sum(vol.values())
    base = parts["base"]
    out = []
    for name in lib.OTHER_GEOMS:
        fr = f'friction="{spec.friction} 0.005 0.0001"'
        if name in _NO_TABLE and not phys.wall_table_contacts:
            # Container walls stand on the base plate's footprint, so they never need a
            # contact with the table: the plate's corners are the lowest points anyway.
            fr += ' contype="2" conaffinity="2"'
        else:
            fr += ' contype="3" conaffinity="3"'
        if name in parts:
            b = parts[name]
            out.append(_box_geom(f"obj_{name}", b.size, b.centre, spec.mass * vol[name] / total,
                                 rgba, fr))
        else:
            size, pos = _collapsed(base.centre)
            out.append(_box_geom(f"obj_{name}", size, pos, 1e-6, rgba, fr))
    return "\n".join(out)


def pair_xml(toy: str, other: str, phys: PhysicsConfig = PhysicsConfig(), arm: bool = False) -> str:
    """MJCF of the scene of one (toy, other) pair; both objects start at the origin."""
    t, o = lib.get(toy), lib.get(other)
    if "toy" not in t.groups:
        raise UserError(f"{toy!r} is not a toy; toys: {', '.join(lib.members('toy'))}")
    if o.group == "toy" and "base" not in o.groups or toy == other:
        raise UserError(f"invalid pair ({toy!r}, {other!r}): one toy plus one object of another group")
    arm_xml = ""
    if arm:
        # The arm's sections go at the top level, with inactive hand welds switched on per
        # scene by the action stage: the held rake, and grasp locks on `obj` / `toy`.
        arm_xml = world_mjcf(tool_body="obj", grasp_bodies=("obj", "toy"),
                             palm_attrs=PALM_MODES[phys.arm_palm_objects])
        excludes = []
        if not phys.arm_pedestal_contacts:
            excludes += [("arm_base", "toy"), ("arm_base", "obj")]
        if phys.arm_palm_objects == "exclude_other":
            excludes += [("arm_hand", "obj")]  # the palm is the hand's one colliding geom
        if excludes:
            arm_xml += ("\n  <contact>" + "".join(f'<exclude body1="{a}" body2="{b}"/>'
                                                  for a, b in excludes) + "</contact>")
        if phys.arm_max_geom_pairs >= 0:
            arm_xml += (f'\n  <custom><numeric name="max_geom_pairs" '
                        f'data="{int(phys.arm_max_geom_pairs)}"/></custom>')
    return f"""
<mujoco model="relaff_{toy}_{other}">
  <option timestep="{phys.timestep}" iterations="{phys.iterations}"
          ls_iterations="{phys.ls_iterations}" solver="{phys.solver}" cone="pyramidal"/>
  <visual><global offwidth="640" offheight="480"/></visual>
  <asset><material name="mat" rgba="0.6 0.6 0.6 1"/></asset>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1"/>
    <geom name="table" type="plane" size="3 3 0.05" material="mat"
          friction="{phys.table_friction} 0.005 0.0001"/>
    <body name="toy">
      <freejoint name="toy_free"/>
      {_toy_geoms(t, phys)}
    </body>
    <body name="obj">
      <freejoint name="obj_free"/>
      {_other_geoms(o, phys)}
    </body>
  </worldbody>
  {arm_xml}
</mujoco>"""


_STACKING = threading.Lock()


@dataclasses.dataclass(frozen=True, eq=False)
class World:
    """Static description of every pair's model; built once in plain Python.

    Attributes:
      pairs: (P,) tuples (toy, other, pairing).
      mj_models: (P,) compiled native models, for the MuJoCo C cross-checks.
      model: mjx.Model whose pair-dependent leaves have a leading (P,) axis.
      model_axes: tree like ``model``: 0 on those leaves, None elsewhere.
      batched_fields: names of the pair-dependent fields.
      (These three are built from ``mj_models`` on first use: a run that simulates in MuJoCo C
      reads none of them until its camera, and the build is ~2 s per world.)
      toy_qpos, obj_qpos: qpos addresses (7 each) of the two free joints.
      toy_dof, obj_dof: dof addresses (6 each).
      geom_seg: (G,) segment label per geom (SEG_*).
      objects: the ``objects.ObjectSet`` the pairs come from.
    """

    phys: PhysicsConfig
    arm: bool
    pairs: tuple[tuple[str, str, str], ...]
    mj_models: tuple[Any, ...]
    toy_qpos: int
    obj_qpos: int
    toy_dof: int
    obj_dof: int
    toy_body: int
    obj_body: int
    geom_seg: np.ndarray
    pair_index: dict
    objects: lib.ObjectSet = lib.BUILTIN_SET  # the set its pairs are made of

    @property
    def _stacked(self) -> tuple[Any, Any, tuple[str, ...]]:
        got = self.__dict__.get("_stacked_models")
        if got is None:
            with _STACKING:  # built once when the camera's warm-up thread and the caller ask at once
                got = self.__dict__.get("_stacked_models")
                if got is None:
                    # eager even when first asked inside a trace (the MJX settle's)
                    with jax.ensure_compile_time_eval():
                        got = self.__dict__["_stacked_models"] = _stack_models(self.mj_models)
        return got

    @property
    def model(self) -> Any:
        return self._stacked[0]

    @property
    def model_axes(self) -> Any:
        return self._stacked[1]

    @property
    def batched_fields(self) -> tuple[str, ...]:
        return self._stacked[2]

    @property
    def n_pairs(self) -> int:
        return len(self.pairs)

    @property
    def mj_model(self):
        """The first pair's native model (structure shared by all pairs)."""
        return self.mj_models[0]

    def pair_id(self, toy: str, other: str) -> int:
        try:
            return self.pair_index[(toy, other)]
        except KeyError:
            self.objects.get(toy), self.objects.get(other)  # unknown names give the listing error
            raise KeyError(f"({toy!r}, {other!r}) is not a valid pair") from None


def _leaves_with_paths(tree):
    return jax.tree_util.tree_flatten_with_path(tree)


def build_world(phys: PhysicsConfig = PhysicsConfig(), arm: bool = False) -> World:
    """Compile every pair of the active object set (``objects.active()``: the 29 built-ins
    unless a run selected others) and stack the fields that differ between pairs. Cached per
    (phys, arm, object set)."""
    return _build_world(phys, arm, lib.active())


@functools.lru_cache(maxsize=4)
def _build_world(phys: PhysicsConfig, arm: bool, objs: lib.ObjectSet) -> World:
    pairs = objs.pairs()
    mj_models = tuple(mujoco.MjModel.from_xml_string(pair_xml(t, o, phys, arm)) for t, o, _ in pairs)
    m0 = mj_models[0]
    jid = lambda n: mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_JOINT, n)
    bid = lambda n: mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_BODY, n)
    seg = np.full(m0.ngeom, SEG_BACKGROUND, np.int32)
    seg[m0.geom_bodyid == bid("toy")] = SEG_TOY
    seg[m0.geom_bodyid == bid("obj")] = SEG_OTHER
    if arm:
        seg[m0.geom_bodyid > bid("obj")] = SEG_HIDDEN  # the arm is not an object of the scene
    return World(
        phys=phys, arm=arm, pairs=pairs, mj_models=mj_models,
        toy_qpos=int(m0.jnt_qposadr[jid("toy_free")]), obj_qpos=int(m0.jnt_qposadr[jid("obj_free")]),
        toy_dof=int(m0.jnt_dofadr[jid("toy_free")]), obj_dof=int(m0.jnt_dofadr[jid("obj_free")]),
        toy_body=bid("toy"), obj_body=bid("obj"), geom_seg=seg,
        pair_index={(t, o): i for i, (t, o, _) in enumerate(pairs)}, objects=objs,
    )


def _stack_models(mj_models: tuple) -> tuple[Any, Any, tuple[str, ...]]:
    """``(model, model_axes, batched_fields)`` of ``World`` from the pairs' native models."""
    mx = [mjx.put_model(m) for m in mj_models]
    flat0, treedef = _leaves_with_paths(mx[0])
    flats = [jax.tree_util.tree_leaves(m) for m in mx]
    leaves, axes, names = [], [], []
    for i, (path, leaf0) in enumerate(flat0):
        vals = [f[i] for f in flats]
        arr0 = np.asarray(leaf0)
        same = all(np.array_equal(np.asarray(v), arr0) for v in vals[1:])
        # `_sizes` only differs in the length of the names buffer: not physics.
        if same or jax.tree_util.keystr(path) == "._sizes":
            leaves.append(leaf0)
            axes.append(None)
        else:
            leaves.append(jnp.stack([jnp.asarray(v) for v in vals]))
            axes.append(0)
            names.append(jax.tree_util.keystr(path))
    return (jax.tree_util.tree_unflatten(treedef, leaves), jax.tree_util.tree_unflatten(treedef, axes),
            tuple(names))


def scene_models(world: World, pair: jax.Array):
    """Gather the models of a batch of scenes.

    Args:
      pair: (B,) int pair indices.
    Returns:
      mjx.Model with a leading (B,) axis on ``world.batched_fields`` (use with
      ``in_axes=(world.model_axes, 0)``).
    """
    leaves, treedef = jax.tree_util.tree_flatten(world.model)
    axes = treedef.flatten_up_to(world.model_axes)
    return jax.tree_util.tree_unflatten(
        treedef, [x if ax is None else x[pair] for x, ax in zip(leaves, axes)])


def batched_step(world: World):
    """``step(models, data) -> data`` for a batch of scenes: vmapped ``mjx.step``.

    Args (of the returned function):
      models: from ``scene_models`` (leading (B,) axis on the pair-dependent fields).
      data: mjx.Data with a leading (B,) axis.
    """
    return jax.vmap(mjx.step, in_axes=(world.model_axes, 0))


def make_data(world: World, qpos: jax.Array) -> Any:
    """Batched mjx.Data at rest at ``qpos`` (B, nq)."""
    d0 = mjx.make_data(world.mj_model)
    return jax.vmap(lambda q: d0.replace(qpos=q))(qpos)
