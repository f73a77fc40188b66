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
