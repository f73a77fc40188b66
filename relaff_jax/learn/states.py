"""State spaces (paper section III-A) and bootstrap inputs (section III-C).

Takes per-action numpy features in the dataset stage's canonical layout (PCA ``(N, 18)``
with the toy's nine values first, RHF ``(N, 300)`` with toy = A, other = B) and gives

* ``state_features``: the state of an action in its own order (manipulated object first),
  ``(N, 18)`` in PCA space or ``(N, 318)`` in RHF space (the paper's), or a derived or
  partial state (``StateConfig``: relative and reach columns added, RHF bins only, named RHF
  sub-histograms), for finding out what a learner relies on;
* ``augment``: a state extended with bootstrap inputs (0/1 predicted classes of other
  affordance or category predictors), each repeated 6 (PCA) or 30 (RHF) times.
"""
from __future__ import annotations

import numpy as np

from relaff_jax.constants import PCA_PER_OBJECT, RHF_BINS, SPACES, TOY_MANIPULATED  # noqa: F401 (re-exported)
from relaff_jax.config.experiment import EXTRAS, RHF_PARTS, StateConfig
from relaff_jax.errors import UserError
from relaff_jax.sim.actions.registry import names



def derived_columns(pca: np.ndarray, extra: tuple[str, ...]) -> np.ndarray:
    """``(N, sum of EXTRAS[e])`` float32 derived columns of canonical ``pca: (N, 18)``."""
    toy, other = pca[:, 0:3].astype(np.float64), pca[:, PCA_PER_OBJECT:PCA_PER_OBJECT + 3].astype(np.float64)
    cols = []
    for e in extra:
        if e == "relative":
            d = toy - other
            cols += [d[:, 0], d[:, 1], d[:, 2], np.hypot(d[:, 0], d[:, 1])]
        elif e == "reach":
            cols += [np.hypot(toy[:, 0], toy[:, 1]), np.hypot(other[:, 0], other[:, 1])]
    return np.stack(cols, axis=1).astype(np.float32) if cols else np.zeros((len(pca), 0), np.float32)


def rhf_columns(parts: tuple[str, ...]) -> np.ndarray:
    """Column indices into the (300,) RHF of the named sub-histograms, in order."""
    per = RHF_BINS // len(RHF_PARTS)
    return np.concatenate([np.arange(per) + per * RHF_PARTS.index(p) for p in parts])


def state_width(space: str, cfg: StateConfig = StateConfig()) -> int:
    """Columns of a state of ``space`` under ``cfg`` (18 / 318 for the paper's)."""
    base = 2 * PCA_PER_OBJECT + sum(EXTRAS[e] for e in cfg.extra)
    if space == "pca":
        return base
    return (base if cfg.rhf_pca else 0) + len(rhf_columns(cfg.rhf_parts))

def manipulated_first_order(action: str) -> np.ndarray:
    """Column order ``(18,)`` that turns canonical PCA (toy first) into the action's order
    (manipulated object first: the spec's ``manipulated``; of the nine, the toy for
    ``TOY_MANIPULATED``, paper Table I)."""
    from relaff_jax.sim.actions.registry import manipulated  # the nine, then the user's (no JAX)

    check_action(action)
    toy, other = np.arange(PCA_PER_OBJECT), np.arange(PCA_PER_OBJECT, 2 * PCA_PER_OBJECT)
    return np.concatenate([toy, other] if manipulated(action) == "toy" else [other, toy])


def state_features(pca: np.ndarray, rhf: np.ndarray | None, action: str | None, space: str,
                   state: StateConfig = StateConfig()) -> np.ndarray:
    """The state of scenes as seen by an ``action``'s predictor.

    pca: (N, 18) canonical PCA (toy's 9 values, then the other object's 9).
    rhf: (N, 300) relational histogram (toy = A, other = B); unused in PCA space.
    action: whose order to use (its manipulated object first); ``None`` keeps the canonical
      order (used by category predictors, whose training data mixes two actions).
    state: derived or partial states (``StateConfig``; default the paper's).
    Returns (N, 18) in PCA space, (N, 318) in RHF space, float32 (``state_width`` columns
    otherwise: PCA in the action's order, then ``state.extra``, then the RHF parts).
    """
    pca = np.asarray(pca, dtype=np.float32)
    if pca.ndim != 2 or pca.shape[1] != 2 * PCA_PER_OBJECT:
        raise ValueError(f"pca features must be (N, 18), got {pca.shape}")
    x = pca if action is None else pca[:, manipulated_first_order(action)]
    if state.extra:
        x = np.concatenate([x, derived_columns(pca, state.extra)], axis=1)
    if space == "pca":
        return np.ascontiguousarray(x)
    if space == "rhf":
        if rhf is None:
            raise ValueError("RHF space needs the rhf features, got None")
        rhf = np.asarray(rhf, dtype=np.float32)
        if rhf.shape != (pca.shape[0], RHF_BINS):
            raise ValueError(f"rhf features must be (N, {RHF_BINS}) matching pca's N={pca.shape[0]}, got {rhf.shape}")
        if state.rhf_parts != RHF_PARTS:
            rhf = rhf[:, rhf_columns(state.rhf_parts)]
        return np.concatenate([x, rhf], axis=1) if state.rhf_pca else np.ascontiguousarray(rhf)
    raise UserError(f"unknown state space {space!r}; expected one of {SPACES}")


def check_action(action: str) -> None:
    if action not in names():
        raise UserError(f"unknown action {action!r}; expected one of {names()}")


def augment(X: np.ndarray, outputs: np.ndarray, repeats: int) -> np.ndarray:
    """State extended with bootstrap inputs.

    X: (N, D) state; outputs: (K, N) 0/1 predicted classes of K predictors on the same scenes.
    Returns (N, D + K * repeats): each predictor's column repeated ``repeats`` times
    (paper V-B: repetition makes the input more likely to be among the sqrt(M) tried
    features at a split).
    """
    outputs = np.asarray(outputs, dtype=np.float32).reshape(-1, X.shape[0])
    if outputs.shape[0] == 0:
        return np.asarray(X, dtype=np.float32)
    return np.concatenate([np.asarray(X, dtype=np.float32), np.repeat(outputs.T, repeats, axis=1)], axis=1)
