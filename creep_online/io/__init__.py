"""Data in: files and live transports. Each source yields samples; nothing bad passes as good."""
from .csvfile import load_csv, save_csv

__all__ = ["load_csv", "save_csv"]

_LAZY = {"open_source", "Sample", "SourceStats", "TransportError", "SampleSource"}


def __getattr__(name: str):
    """Live sources on first use (``creep_online.io.open_source``); pyserial/python-can load only when opened."""
    if name in _LAZY:
        from . import sources
        return getattr(sources, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
