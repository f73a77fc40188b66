"""A condition plugin: the other actions' predictors as a vote instead of one column each.

Register it with the experiment and name it among the conditions:
  relaff experiment ... --plugins vote_condition.py \\
                        --set 'experiment.conditions_pca=["NB","DB1","DBn","CB1","CBn","VOTE"]'
It adds two learners per target, VOTE:share and VOTE:any, after the paper's conditions.
"""
import numpy as np

from relaff_jax.learn import Knowledge, register_condition


@register_condition("VOTE")
def vote(k: Knowledge) -> dict[str, np.ndarray]:
    """The share of the other actions' source predictors that say yes, and whether any does,
    each repeated as the paper repeats a bootstrap input (k.repeats columns)."""
    said = np.stack(list(k.sources.values()))  # (A - 1, N) 0/1
    return {"share": k.repeated(said.mean(0)), "any": k.repeated(said.max(0))}
