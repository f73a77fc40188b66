"""Rotations shared by the arm's kinematics and the motor programs.

Takes quaternions / axis-angle pairs; gives (3, 3) rotation matrices. Pure functions.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp


def quat_to_mat(q, xp=jnp):
    """(3, 3) rotation matrix of a quaternion ``q`` (4,) in MuJoCo's (w, x, y, z) order,
    normalised first.

    ``xp`` is the array module: ``jax.numpy`` (default; traced, float32 under jit) or
    ``numpy`` for float64 model constants (``arm.arm_from_model``). One formula for both.
    """
    w, x, y, z = q / xp.linalg.norm(q)
    return xp.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def axis_rotation(axis: jax.Array, angle: jax.Array) -> jax.Array:
    """Rodrigues: (3, 3) rotation by ``angle`` () about the unit ``axis`` (3,)."""
    x, y, z = axis[0], axis[1], axis[2]
    k = jnp.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return jnp.eye(3) + jnp.sin(angle) * k + (1.0 - jnp.cos(angle)) * (k @ k)
