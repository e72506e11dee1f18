"""Exception types: every user-facing failure is one of these, with a one-line message."""
from __future__ import annotations

import re


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


#: Characters a terminal may act on (C0 but tab/newline/return, DEL, C1, bidirectional overrides) and the lone
#: surrogates that stand for undecodable bytes of a file name: never shown raw.
_CONTROL = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\ud800-\udfff]")


def _escape(match: re.Match) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def printable(text: str, *, keep_return: bool = True) -> str:
    """``text`` with every control character a terminal would act on written as ``\\xNN`` (a file name or a
    CSV header may hold escape sequences that set the window title or clear the screen). Tab and newline
    stay; carriage return too unless ``keep_return`` is False."""
    text = _CONTROL.sub(_escape, text)
    return text if keep_return else text.replace("\r", "\\x0d")


def one_line(exc: BaseException) -> str:
    """The exception's message on one line (first line, at most 500 characters: room for a file's path and the
    list of its channels or columns; control characters escaped): how every error is shown."""
    text = str(exc).strip().splitlines()
    return printable((text[0] if text else type(exc).__name__)[:500], keep_return=False)
