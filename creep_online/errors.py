"""Exception types: every user-facing failure is one of these, with a one-line message."""
from __future__ import annotations


class CreepOnlineError(Exception):
    """Base class: the CLI prints the message on one line and exits with code 2."""


class ModelError(CreepOnlineError, ValueError):
    """Invalid model parameters (e.g. alpha outside (0, 1))."""


class DataError(CreepOnlineError, ValueError):
    """A data file or array that cannot be used, with the reason."""


class IdentificationError(CreepOnlineError, RuntimeError):
    """Identification could not produce an estimate from the data."""


class TransportError(CreepOnlineError):
    """A live source could not be opened or was lost for good (port, adapter, plug-in); one-line message.

    ``creep-online stream`` ends with exit code 4 when the link is lost after samples
    arrived (docs/reliability.md).
    """


class OutputError(CreepOnlineError, OSError):
    """An output file or folder that cannot (or must not) be written, with the reason."""


class CreepOnlineWarning(UserWarning):
    """Something the user should know that does not stop the run; the CLI prints it on one line."""


class DataWarning(CreepOnlineWarning):
    """A doubtful but usable data file (e.g. a last line without end-of-line)."""


def one_line(exc: BaseException) -> str:
    """The exception's message on one line (first line, at most 500 characters: room for a file's path and the
    list of its channels or columns): how every error is shown."""
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__)[:500]
