"""The one exception type for mistakes a user can fix (a bad option, a folder that cannot be
used, corrupt or mismatched data on disk).

The CLI prints a ``UserError`` as one line, ``relaff COMMAND: error: MESSAGE``, exit code 2.
Every other exception is a bug or an environment failure and keeps its traceback.
"""
from __future__ import annotations


class UserError(ValueError):
    """A problem with the user's input; its message says what is wrong and how to fix it.

    Subclasses ``ValueError`` so that library callers catching ``ValueError`` keep working.
    """


class CorruptFileError(UserError):
    """A file on disk that cannot be read as what it should be (corrupt JSON, a truncated
    ``.npz``, a file of another program); the message names the file."""


class DiskFullError(UserError):
    """A write failed because its file system is full (ENOSPC) or over quota (EDQUOT); the
    message names the folder and the space it had. What was finished before is kept."""
