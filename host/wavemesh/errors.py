"""One error family for everything a user can cause.

The CLI turns a :class:`WavemeshError` into one line ``error: <message>``
(plus ``hint: <hint>`` when there is one) and a non-zero exit status; any other
exception is a bug and keeps its traceback.
"""


class WavemeshError(Exception):
    """An error the user can cause and fix (bad input, bad option, bad device)."""

    exit_code = 2

    def __init__(self, message: str, hint: str | None = None):
        super().__init__(message)
        self.message = message
        self.hint = hint


class InputError(WavemeshError):
    """A height field or mesh file that cannot be read or is not acceptable."""


class MeshInvalid(WavemeshError):
    """A mesh that is not a proper triangulation of the grid rectangle."""

    exit_code = 1
