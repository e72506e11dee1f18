"""The options a sample source declares, and the parsing of a spec's ``?key=value&...`` against them.

Every source class lists its own options (``SampleSource.options``): the key
used in a spec, how its text is converted, its default and a line of help.
``open_source`` checks a spec against the chosen source's list only, so a
misspelt or foreign key is a one-line error naming the source and its
options, never a keyword silently thrown away (docs/transports.md, "Adding a
source").
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable
from urllib.parse import parse_qsl

from ..errors import DataError

_FALSE = ("0", "false", "no", "off")
_TRUE = ("1", "true", "yes", "on", "")


def flag(text: str) -> bool:
    """``1/true/yes/on`` (or a bare key) -> True, ``0/false/no/off`` -> False; anything else is refused."""
    value = text.strip().lower()
    if value in _FALSE:
        return False
    if value in _TRUE:
        return True
    raise ValueError(f"expected 0 or 1, got {text!r}")


#: The largest number an option of a source takes (a rate in Hz, a time in s, a range): beyond it a value is a
#: unit mistake (and a socket's timeout or a sample step would overflow).
OPTION_MAX = 1e9


def positive(text: str) -> float:
    """A finite number > 0 and at most OPTION_MAX (a rate, a time, a range)."""
    value = float(text)
    if not (math.isfinite(value) and 0 < value <= OPTION_MAX):
        raise ValueError(f"expected a positive number up to {OPTION_MAX:g}")
    return value


def nonzero(text: str) -> float:
    """A finite non-zero number (a scale)."""
    value = float(text)
    if not (math.isfinite(value) and value != 0 and abs(value) <= OPTION_MAX):
        raise ValueError(f"expected a non-zero number up to {OPTION_MAX:g} in size")
    return value


def whole(minimum: int) -> Callable[[str], int]:
    """A converter for a whole number >= ``minimum`` (a count, a channel)."""
    def convert(text: str) -> int:
        value = int(text)
        if value < minimum or value > 1 << 31:
            raise ValueError(f"expected a whole number from {minimum} to {1 << 31}")
        return value
    convert.__name__ = "int"
    return convert


def port_number(text: str) -> int:
    """A TCP port: a whole number from 1 to 65535."""
    value = int(text)
    if not 1 <= value <= 65535:
        raise ValueError("expected a TCP port from 1 to 65535")
    return value


def nonempty(value: str) -> str:
    """Any non-empty text (a file name, a column name)."""
    if not value.strip():
        raise ValueError("expected a non-empty value")
    return value


def choice(*allowed: str) -> Callable[[str], str]:
    """A converter that accepts one of ``allowed`` (case-insensitive) and returns it in lower case."""
    def convert(text: str) -> str:
        value = text.strip().lower()
        if value not in allowed:
            raise ValueError(f"expected one of {', '.join(allowed)}")
        return value
    convert.__name__ = "|".join(allowed)
    return convert


@dataclass(frozen=True)
class Option:
    """One ``?key=value`` option of a source.

    ``convert`` turns the spec's text into the value passed to the source's
    constructor as keyword ``keyword`` (the key itself unless it differs, e.g.
    ``baud`` -> ``baudrate``). ``default`` is the constructor's own default,
    shown in help and checked against the signature by the tests.
    """

    name: str
    convert: Callable[[str], Any] = str
    default: Any = None
    help: str = ""
    keyword: str | None = None
    path: bool = False      # the value names a file the source reads (never an output of the same run)

    @property
    def argument(self) -> str:
        """The constructor keyword this option fills."""
        return self.keyword or self.name

    def with_default(self, default: Any) -> "Option":
        """The same option with another default (e.g. a larger reorder window for CAN)."""
        return Option(self.name, self.convert, default, self.help, self.keyword, self.path)

    def describe(self) -> str:
        """``name=TYPE (default D): help`` for listings."""
        kind = getattr(self.convert, "__name__", "text").replace("str", "text").replace("positive", "float") \
            .replace("nonzero", "float")
        return f"{self.name}={kind} (default {self.default!r}): {self.help}"


# Options shared by several sources (each source lists the ones it takes).
RATE = Option("rate", positive, None, "sample rate in Hz (frames that carry a counter, not a time)")
WINDOW = Option("window", whole(0), 16, "reorder window in samples")
STALL = Option("stall", positive, 0.5, "seconds of silence counted as a stall")
RECONNECT = Option("reconnect", flag, True, "reopen a lost link with backoff (0: give up at once)")
#: How long a lost link is reopened before the stream ends with "link lost" (a device that never comes back
#: must not hold a stream, or the service running it, forever).
RECONNECT_TIMEOUT_S = 60.0
RECONNECT_TIMEOUT = Option("reconnect_timeout", positive, RECONNECT_TIMEOUT_S,
                           "give up reconnecting after this many seconds")
#: How long a live link may deliver nothing at all before the stream ends with "link lost".
IDLE_TIMEOUT_S = 60.0
IDLE_TIMEOUT = Option("idle_timeout", positive, IDLE_TIMEOUT_S,
                      "end the stream after this many seconds without a sample on a connected link")
REALTIME = Option("realtime", flag, False, "pace a replay in real time")
DBC = Option("dbc", nonempty, None, "DBC file with the amplifier's messages (default: the packaged one)", path=True)


def split_query(rest: str) -> tuple[str, list[tuple[str, str]]]:
    """``TARGET?k=v&k2=v2`` -> (TARGET, [(k, v), (k2, v2)]); no ``?`` -> (rest, [])."""
    if "?" not in rest:
        return rest, []
    target, query = rest.split("?", 1)
    return target, parse_qsl(query, keep_blank_values=True)


def convert_options(spec: str, declared: Iterable[Option], pairs: list[tuple[str, str]],
                    *, keep_unknown: bool = False) -> tuple[dict[str, Any], list[tuple[str, str]]]:
    """Check ``pairs`` against the ``declared`` options and convert them to constructor keywords.

    Returns (keywords, unknown pairs). An unknown key is an error unless
    ``keep_unknown`` (a serial URL keeps pyserial's own ``?options``).
    """
    by_name = {o.name: o for o in declared}
    out: dict[str, Any] = {}
    unknown: list[tuple[str, str]] = []
    for key, text in pairs:
        option = by_name.get(key)
        if option is None:
            if not keep_unknown:
                names = ", ".join(sorted(by_name)) or "none"
                raise DataError(f"{spec}: unknown option {key!r} for this source (options: {names})")
            unknown.append((key, text))
            continue
        try:
            out[option.argument] = option.convert(text)
        except ValueError as exc:
            why = str(exc).splitlines()[0] if str(exc) else ""
            hint = f" ({why})" if why and option.convert not in (int, float) else ""
            raise DataError(f"{spec}: option {key}={text!r} is not valid{hint}") from None
    return out, unknown
