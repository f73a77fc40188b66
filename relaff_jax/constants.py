"""Names shared by every stage, defined once.

The order of each tuple is part of the stored formats: datasets store relation and segment
codes as indices into these tuples, and result arrays are laid out in ``ACTIONS`` order.
"""
from __future__ import annotations
from relaff_jax.errors import UserError

# The nine actions of the paper's Table I, in the order of every result array.
ACTIONS = ("lift", "move", "pull", "push", "rake", "take", "pour", "slide", "unobstruct")

# Object pairings (``sim.objects.PAIRINGS`` order) and the pairing each action is tried on.
PAIRINGS = ("toy+base", "toy+obstacle", "toy+rake")
PAIRING = {"lift": 0, "move": 0, "pull": 0, "push": 0, "take": 0, "pour": 0, "slide": 0,
           "unobstruct": 1, "rake": 2}
# The object each action's program moves (paper Table I): the toy for these, the other object
# (base, obstacle, rake) for the rest; its nine PCA values come first in the action's state.
TOY_MANIPULATED = frozenset({"move", "take"})

# Spatial relation of a settled pair; datasets store the index.
RELATIONS = ("beside", "on_top", "inside")
BESIDE, ON_TOP, INSIDE = 0, 1, 2

# Segment label per geom and per camera pixel (the colour segmentation of paper IV-A).
# SEG_HIDDEN: a geom the camera does not report (the arm); SEG_NONE: a pixel with no return.
SEG_BACKGROUND, SEG_TOY, SEG_OTHER, SEG_HIDDEN = 0, 1, 2, -1
SEG_NONE = -1
OBJECT_SEGMENTS = (SEG_TOY, SEG_OTHER)

# State spaces of the learning experiment (paper V-A).
# Executors of the planned motor programs (sim/rollouts.py): MJX (default; also runs on an
# accelerator) and MuJoCo C batches on a thread pool (sim/native/batch.py).
SIM_ENGINES = ("mjx", "native")

SPACES = ("pca", "rhf")
PCA_PER_OBJECT = 9
RHF_BINS = 300

# The bootstrapping conditions of paper section V.
FAMILIES = ("NB", "DB1", "DBn", "CB1", "CBn")

# The stages of ``relaff reproduce``, in order.
STAGES = ("generate", "features", "experiment", "report")


def action_id(action: str) -> int:
    """Index of ``action`` in ``ACTIONS``; an unknown name is a ``UserError`` listing the valid ones.
    (The run's list, with a user's actions after the nine: ``sim.actions.registry.action_id``.)"""
    if action not in ACTIONS:
        raise UserError(f"unknown action {action!r}; valid actions: {', '.join(ACTIONS)}")
    return ACTIONS.index(action)
