"""Levenberg-Marquardt descent of the arm's IK residual: the ``ik_solver="lm"`` option.

Takes the ``Arm`` tables, an ``ArmConfig``, a start ``q0`` (6,) and one ``IKTarget``; gives
``descend_lm``, the joints after ``cfg.ik_lm_steps`` damped Gauss-Newton steps on the same
9-vector residual as the default L-BFGS (``kinematics._residual``), each step projected onto
the joint limits by clipping and kept only if it lowers the squared residual (the damping
then falls, else it rises). Fixed work per step (one Jacobian, one 6x6 solve, one residual),
no line search: under ``vmap`` the L-BFGS zoom line search runs every lane as long as the
slowest (20 evaluations per step once a lane's residual is at float32 noise), this does not.
One sample; the caller vmaps and jits. Plans differ from L-BFGS's (``docs/arm.md``, "IK
solvers"), so the option is recorded with the action config.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from relaff_jax.config.action import ArmConfig

from .arm_model import Arm


def descend_lm(arm: Arm, cfg: ArmConfig, q0: jax.Array, target, residual) -> jax.Array:
    """``q`` (6,) after ``cfg.ik_lm_steps`` accepted-or-rejected LM steps from ``q0`` (6,).

    ``residual(arm, cfg, q, target) -> (9,)`` is the IK residual (passed in to keep this
    module below ``kinematics`` in the import graph)."""
    res = lambda q: residual(arm, cfg, q, target)
    eye = jnp.eye(6, dtype=jnp.float32)

    def step(carry, _):
        q, f, lam = carry
        r = res(q)
        jac = jax.jacfwd(res)(q)  # (9, 6)
        h = jac.T @ jac
        g = jac.T @ r
        # Marquardt's scaling (damping proportional to the curvature per joint) plus a floor
        dq = -jnp.linalg.solve(h + lam * (jnp.diag(jnp.diag(h)) + 1e-6 * eye), g)
        q_new = jnp.clip(q + dq, arm.q_lo, arm.q_hi)
        f_new = jnp.sum(res(q_new) ** 2)
        better = f_new < f
        return (jnp.where(better, q_new, q), jnp.where(better, f_new, f),
                jnp.where(better, lam * 0.3, lam * 10.0)), None

    q0 = jnp.asarray(q0, jnp.float32)
    f0 = jnp.sum(res(q0) ** 2)
    (q, _, _), _ = jax.lax.scan(step, (q0, f0, jnp.float32(1e-3)), None, length=cfg.ik_lm_steps)
    return q
