"""The dataset stage's error types, all ``relaff_jax.errors.UserError`` (a user can fix them:
a bad argument, a folder that cannot be used, corrupt or mismatched data on disk).

Takes nothing; gives ``DatasetError`` and its subclasses ``ForeignDirectoryError``,
``DatasetMismatchError``, ``CorruptDatasetError``, ``RolloutCapError``.
"""
from __future__ import annotations

from relaff_jax.errors import UserError


class DatasetError(UserError):
    """Bad dataset input or a dataset directory that cannot be used."""


class ForeignDirectoryError(DatasetError):
    """The directory exists but is not a relaff dataset."""


class DatasetMismatchError(DatasetError):
    """Resuming a dataset with a different action, seed, batch, N or config."""


class CorruptDatasetError(DatasetError):
    """A missing, truncated or corrupt chunk, sidecar or index."""


class RolloutCapError(DatasetError):
    """The rollout cap was reached before a balanced selection existed."""
