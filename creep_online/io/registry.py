"""Which class opens which kind of source: a name -> ``"module:Class"`` registry, imported lazily.

Shaped like python-can's interfaces: the built-in kinds are listed here by
module path (so pyserial or python-can load only when such a source is
opened), a third party adds kinds through entry points in the group
``creep_online.sources`` (``name = "package.module:Class"``) or in-process
with :func:`register_source`. A spec ``KIND:TARGET?key=value&...`` is then
opened by the kind's class, checked against the options that class declares
(docs/transports.md, "Adding a source").
"""
from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any

from ..errors import DataError, TransportError
from .source_options import convert_options, split_query

if TYPE_CHECKING:  # only for the annotations: the base module is imported when a source is opened
    from .sources import SampleSource

#: Entry-point group through which installed distributions add source kinds.
ENTRY_POINT_GROUP = "creep_online.sources"

#: The kinds shipped with creep_online.
BUILTIN_SOURCES: dict[str, str] = {
    "csv": "creep_online.io.csv_source:CsvSource",
    "serial": "creep_online.io.serial_source:SerialSource",
    "can": "creep_online.io.can_source:CanSource",
    "canlog": "creep_online.io.canlog_source:CanLogSource",
    "pi": "creep_online.io.pi_source:PiSource",
    "capancdt": "creep_online.io.capancdt_source:CapancdtSource",
}

_registered: dict[str, str | type] = {}      # register_source(): wins over everything else
_from_entry_points: dict[str, str] | None = None


def register_source(name: str, target: "str | type[SampleSource]", *, replace: bool = False) -> None:
    """Make ``name:TARGET`` specs open with ``target`` (a class or ``"module:Class"``).

    A name already taken (built in, registered, or from an entry point) is
    refused unless ``replace=True``.
    """
    key = _kind(name)
    if not replace and key in available_sources():
        raise ValueError(f"source kind {key!r} is already registered (pass replace=True to override it)")
    if isinstance(target, str) and ":" not in target:
        raise ValueError(f"source target must be 'module:Class', got {target!r}")
    _registered[key] = target


def unregister_source(name: str) -> None:
    """Forget a kind added with :func:`register_source` (built-in and entry-point kinds stay)."""
    _registered.pop(_kind(name), None)


def available_sources() -> dict[str, str]:
    """Every known kind -> where its class lives (``"module:Class"``), built-in kinds first."""
    table = dict(BUILTIN_SOURCES)
    for name, target in _entry_point_sources().items():
        table.setdefault(name, target)
    for name, target in _registered.items():
        table[name] = target if isinstance(target, str) else f"{target.__module__}:{target.__qualname__}"
    return table


def refresh_entry_points() -> None:
    """Read the ``creep_online.sources`` entry points again (after installing a plug-in in this process)."""
    global _from_entry_points
    _from_entry_points = None


def _entry_point_sources() -> dict[str, str]:
    """Kinds declared by installed distributions; a built-in name cannot be taken over this way."""
    global _from_entry_points
    if _from_entry_points is None:
        found: dict[str, str] = {}
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            name = _kind(ep.name)
            if name not in BUILTIN_SOURCES:
                found.setdefault(name, ep.value)
        _from_entry_points = found
    return _from_entry_points


def _kind(name: str) -> str:
    return name.strip().lower()


def source_class(name: str) -> "type[SampleSource]":
    """The class that opens ``name:`` specs, imported now; one-line errors for unknown or broken kinds."""
    from .sources import SampleSource
    key = _kind(name)
    target = _registered.get(key) or available_sources().get(key)
    if target is None:
        raise DataError(f"unknown source kind {key!r} ({', '.join(available_sources())})")
    cls = target if not isinstance(target, str) else _load(key, target)
    if not (isinstance(cls, type) and issubclass(cls, SampleSource)):
        raise TransportError(f"source kind {key!r}: {target} is not a SampleSource subclass")
    return cls


def _load(kind: str, target: str) -> Any:
    module_name, _, attr = target.partition(":")
    try:
        obj: Any = importlib.import_module(module_name.strip())
        for part in attr.strip().split("."):
            obj = getattr(obj, part)
    except ImportError as exc:
        raise TransportError(f"source kind {kind!r} needs {exc.name or module_name}, which is not installed") from None
    except AttributeError:
        raise TransportError(f"source kind {kind!r}: {target} does not exist") from None
    return obj


def open_source(spec: str, **options: Any) -> "SampleSource":
    """Open ``KIND:TARGET?key=value&...`` with the kind's class (see docs/transports.md for the kinds).

    Spec options are checked and converted against the options the class
    declares; keyword ``options`` (e.g. ``on_event``) go to the constructor
    as they are and win over the spec's.
    """
    cls, kind, rest = _spec_class(spec)
    target, pairs = split_query(rest)
    keywords, unknown = convert_options(spec, cls.options, pairs, keep_unknown=cls.keeps_unknown_options)
    if unknown:   # stays part of the target (pyserial URL options)
        target += "?" + "&".join(f"{k}={v}" if v else k for k, v in unknown)
    if not target:
        raise DataError(f"{spec!r}: missing {cls.target_label} after '{_kind(kind)}:'")
    return cls.from_spec(spec, target, **{**keywords, **options})


def _spec_class(spec: str) -> tuple["type[SampleSource]", str, str]:
    """(class, kind, rest after 'KIND:') of a spec; DataError for a spec without a known, lower-case kind."""
    if not isinstance(spec, str) or ":" not in spec:
        raise DataError(f"{spec!r}: not a source spec (use {_kinds_hint()})")
    kind, rest = spec.split(":", 1)
    if kind != kind.strip().lower():
        raise DataError(f"{spec!r}: source kinds are written in lower case ({_kind(kind)}:...)")
    try:
        return source_class(kind), kind, rest
    except DataError as exc:
        raise DataError(f"{spec!r}: {exc}") from None


def spec_files(spec: str) -> list[str]:
    """The files a spec's source reads (a file target, ``?dbc=``, ``?command=``): outputs of the same run must
    not be any of them. Empty for a spec that does not open (``open_source`` says why)."""
    try:
        cls, _, rest = _spec_class(spec)
    except (DataError, TransportError):
        return []
    target, pairs = split_query(rest)
    paths = {o.name for o in cls.options if o.path}
    files = [value for key, value in pairs if key in paths and value]
    if cls.target_is_file and target:
        files.insert(0, target)
    return files


def _kinds_hint() -> str:
    examples = {"csv": "csv:FILE", "serial": "serial:PORT", "can": "can:IFACE:CHANNEL", "canlog": "canlog:FILE", "pi": "pi:PORT",
                "capancdt": "capancdt:HOST:PORT"}
    return ", ".join(examples.get(k, f"{k}:...") for k in available_sources())
