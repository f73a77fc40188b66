"""The user's conditions in the sweep (``conditions.py`` registers them): each target's
``Knowledge`` from the prep, the learners they add after the built-ins on the condition axis
(``extend``: extra bootstrap rows, used once each, and their plan entries), the record of
their sources for ``experiment.json`` (``record``) and the built-ins' view of a results
file that Table II reads (``builtin_results``).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from relaff_jax.learn.conditions import Knowledge, columns, custom_names, registered
from relaff_jax.learn.correlation import category_pairs
from relaff_jax.constants import SPACES


def knowledge(target: str, actions: list[str], state: np.ndarray, boot: np.ndarray, corr: np.ndarray,
              allowed: np.ndarray, repeats: int, thresholds: tuple[float, ...]) -> Knowledge:
    """The ``Knowledge`` of target ``target`` from the prep's bootstrap inputs ``boot: (A + K, M)``
    (source predictors, then categories; NaN rows for categories a space does not build) and
    ``allowed: (K,)`` the categories the target may use."""
    a = len(actions)
    ti = actions.index(target)
    pairs = category_pairs(actions)
    sources = {s: boot[i] for i, s in enumerate(actions) if i != ti}
    cats = {(actions[i], actions[j]): boot[a + k] for k, (i, j) in enumerate(pairs)
            if allowed[k] and np.all(np.isfinite(boot[a + k]))}
    return Knowledge(target, tuple(actions), state, sources, cats, np.asarray(corr), int(repeats), tuple(thresholds))


@dataclasses.dataclass
class Extension:
    """The user's conditions of one space's sweep: ``names`` appended to the condition axis;
    per target the extra bootstrap rows ``rows[t]: (E_t, M_t)`` (each used once, not repeated)
    and the plan entries ``plans[t]`` indexing them after the prep's rows."""

    names: list[str]
    rows: dict[str, np.ndarray]
    plans: dict[str, list[tuple[int, tuple[int, ...]]]]

    def boot(self, t: str, boot: np.ndarray) -> np.ndarray:
        """The prep's bootstrap inputs of target t, then its extra rows."""
        return np.concatenate([boot, self.rows[t]]) if t in self.rows and len(self.rows[t]) else boot

    def repeats(self, t: str, repeats: int, n_boot: int) -> int | np.ndarray:
        """Repetitions per bootstrap row: the paper's for the prep's ``n_boot`` rows, 1 for the
        extra rows (an int when there are none: the built-ins' path unchanged)."""
        e = len(self.rows.get(t, ()))
        return repeats if not e else np.concatenate([np.full(n_boot, repeats), np.ones(e, int)])


def extend(states: Mapping[str, np.ndarray], prep: Mapping[str, np.ndarray], actions: list[str], cfg: Any,
           space: str, allowed: np.ndarray, first: int) -> Extension:
    """The user's conditions of ``space`` on every target pool. ``states[t]: (M_t, D)`` the
    target's pool states, ``allowed: (A, K)`` the categories each target may use, ``first`` the
    condition index of the first user learner. Every learner name any target gives is on the
    axis (a target without it: NaN there)."""
    names_wanted = custom_names(cfg, space)
    if not names_wanted:
        return Extension([], {}, {})
    reg = registered()
    per_target = {}
    for ti, t in enumerate(actions):
        k = knowledge(t, actions, states[t], prep[f"boot:{t}"], prep["corr"], allowed[ti], cfg.repeats(space),
                      cfg.thresholds)
        per_target[t] = [item for n in names_wanted for item in columns(reg[n], k)]
    names = list(dict.fromkeys(n for t in actions for n, _ in per_target[t]))
    rows, plans = {}, {}
    for t in actions:
        base = len(prep[f"boot:{t}"])
        cols, plan = [], []
        for name, c in per_target[t]:
            plan.append((first + names.index(name), tuple(range(base + sum(x.shape[1] for x in cols),
                                                                base + sum(x.shape[1] for x in cols) + c.shape[1]))))
            cols.append(c)
        rows[t] = np.concatenate(cols, axis=1).T if cols else np.zeros((0, len(states[t])), np.float32)
        plans[t] = plan
    return Extension(names, rows, plans)


def record(cfg: Any) -> dict[str, dict[str, str]]:
    """``{name: {"origin", "sha256"}}`` of the user's conditions ``cfg`` runs (for experiment.json:
    a folder never silently changes what a condition name meant)."""
    names = dict.fromkeys(n for s in SPACES for n in custom_names(cfg, s))
    if not names:
        return {}
    reg = registered()
    return {n: {"origin": reg[n].origin, "sha256": reg[n].sha256} for n in names if n in reg}


def builtin_results(res: Mapping[str, Any], n_builtin: int) -> Mapping[str, Any]:
    """``res`` with the condition axis cut to the built-ins' ``n_builtin`` (what Table II and its
    intervals read); unchanged when there are no user conditions."""
    if np.shape(res["acc"])[1] == n_builtin:
        return res
    cut = {k: res[k] for k in res.keys()}
    for k in ("acc", "loo", "acc_subset"):
        if k in cut:
            cut[k] = np.asarray(cut[k])[:, :n_builtin]
    c = cut.get("correct")
    if c is not None:  # bit-packed outcomes (results.PackedBits) stay packed
        cut["correct"] = type(c)(c.packed[:, :n_builtin], c.n) if hasattr(c, "packed") else np.asarray(c)[:, :n_builtin]
    cut["conditions"] = np.asarray(res["conditions"])[:n_builtin]
    return cut
