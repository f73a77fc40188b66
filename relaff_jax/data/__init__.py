"""Datasets: chunked, resumable, balanced stores of labelled rollouts and their features
(paper section IV-D).

Public API::

    generate_dataset(out_dir, action, rollout_fn, seed, config_dict, dataset_config=...) -> summary
        (N and the chunk's batch: the node's ``n_samples`` and ``rollout_batch``)
    load_dataset(dir)  -> dict of (N, ...) arrays of the selected samples (+ features, + action)
    load_rollouts(dir) -> dict of (R, ...) arrays of every rollout (+ ``selected`` mask)
    add_features(dir, compute_fn, batch)  -> attaches (N, ...) feature arrays (pca, rhf, ...)
    dataset_status(dir, expected) / features_status(dir, batch, config) -> (state, why)
    info(dir) -> counts and positive rates;  export_dataset(dir, out) -> Parquet + schema + card
    anatomy(dir) -> what the labels consist of: reach (feasible) or relation, with oracles

Files (one job each):

* ``errors.py``    ``DatasetError`` (a ``relaff_jax.errors.UserError``) and its subclasses;
* ``layout.py``    folder layout names, argument checks (settings: ``relaff_jax.config.dataset``);
* ``selection.py`` ``select_balanced``: N/2 positives, COG-distance-matched (or uniform)
  negatives, from every rollout or the feasible ones (``POPULATIONS``, ``NEGATIVES``);
* ``validate.py``  rollout/feature outputs to storage types, per-field schemas;
* ``store.py``     orbax chunks (write, verified read), sidecar, writer lock, folder set-up;
* ``progress.py``  tqdm progress bars;
* ``generate.py``  ``generate_dataset`` (resumable, deterministic);
* ``load.py``      ``load_rollouts``, ``load_dataset``, feature-chunk reading;
* ``features.py``  ``add_features`` (resumable, ``overwrite`` recomputes);
* ``status.py``    ``dataset_status``, ``features_status``, and their progress fractions;
* ``info.py``      ``info``, ``format_info``;
* ``anatomy.py``   ``anatomy``, ``format_anatomy``: labels by (feasible, relation), oracles;
* ``export.py``    ``export_dataset``: Parquet, JSON schema of the features, dataset card.
* ``show.py``      ``show_sample``: one sample drawn (PNG) or replayed (GIF), ``relaff show``.

The ``relaff info``, ``relaff anatomy`` and ``relaff export`` commands are in ``relaff_jax.cli.data``.
Layout, selection scheme and error cases: ``docs/datasets.md``.
"""
from relaff_jax.constants import ACTIONS, RELATIONS
from relaff_jax.data.layout import (CHUNKS, FEATURES, FEATURES_SIDECAR, FORMAT, FORMAT_VERSION, LOCK, REQUIRED_FIELDS, RESERVED_FIELDS, SELECTION, SIDECAR)
from relaff_jax.data.errors import (CorruptDatasetError, DatasetError, DatasetMismatchError,
                                    ForeignDirectoryError, RolloutCapError)
from relaff_jax.data.anatomy import anatomy, anatomy_of, format_anatomy
from relaff_jax.data.export import export_dataset
from relaff_jax.data.features import add_features
from relaff_jax.data.generate import generate_dataset
from relaff_jax.data.info import format_info, info
from relaff_jax.data.load import load_dataset, load_rollouts
from relaff_jax.config.dataset import NEGATIVES, POPULATIONS
from relaff_jax.data.selection import Selection, select_balanced
from relaff_jax.data.status import dataset_status, features_progress, features_status, generation_progress

__all__ = [
    "ACTIONS", "RELATIONS", "CHUNKS", "FEATURES", "FEATURES_SIDECAR", "FORMAT", "FORMAT_VERSION", "LOCK",
    "REQUIRED_FIELDS", "RESERVED_FIELDS", "SELECTION", "SIDECAR",
    "DatasetError", "ForeignDirectoryError", "DatasetMismatchError", "CorruptDatasetError", "RolloutCapError",
    "export_dataset", "add_features", "generate_dataset", "format_info", "info", "load_dataset",
    "load_rollouts", "Selection", "select_balanced", "dataset_status", "features_status",
    "generation_progress", "features_progress", "anatomy", "anatomy_of", "format_anatomy", "NEGATIVES", "POPULATIONS",
]
