"""The random streams of a run, by name. Each stage derives its seeds from the run's seed and a
stream id (``provenance.derive_seed(seed, STREAM, ...)``), so that no two stages share a stream.
The ids are part of every stored result: never change a value, only add new ones."""
from __future__ import annotations

# derive_seed(seed, RUN_FOLDER, 1, action) / (seed, RUN_FOLDER, 2): a reproduce folder's
# dataset and feature seeds (reproduce/folder.py)
RUN_FOLDER = 0x5EED
POOL_SPLIT = 1  # learn/protocol.py: the permutation that cuts an action's pool
SOURCE_FOREST = 2  # learn/prep.py: the source predictors' forests
CATEGORY_FOREST = 3  # learn/prep.py: the category predictors' forests
TEST_DRAW = 4  # learn/draws.py: the balanced test set per target
SWEEP_FOREST = 5  # learn/sweep.py: every forest of the sweep (with SPACE_CODE, target, repetition)
TRAIN_DRAW = 6  # learn/draws.py: the training draws per target and repetition
INTERVALS = 7  # learn/analysis.py: the bootstrap resamples of the intervals
SIM_RELATIONS = 16  # real/sim_relations.py: the simulated relation scenes (0: chunks, 1: noise root)
REAL_EXPERIMENT = 17  # real/experiments.py: the real experiments' draws and forests
SIM_TO_SIM = 18  # real/experiments.py: SIM -> SIM pairs
REAL_SPLIT = 19  # real/splits.py: train/test cuts of the real pairs
IMPROVEMENT = 23  # learn/analysis.py: the probability-of-improvement resamples

# np.random.SeedSequence([seed, SELECT_SALT]): the dataset selection's own stream (data/selection.py)
SELECT_SALT = 0x5E1EC7
# np.random.SeedSequence([seed, SYNTHETIC]): synthetic knowledge for tests and --synthetic (learn/synthetic.py)
SYNTHETIC = 7

# Integer code of each state space in seed keys (part of every forest's seed: never change).
SPACE_CODE = {"pca": 0, "rhf": 1}

STREAMS = {k: v for k, v in dict(globals()).items() if k.isupper() and isinstance(v, int)}
