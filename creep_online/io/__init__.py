"""Data in: files and live transports. Each source yields samples; nothing bad passes as good."""
from .csvfile import load_csv, save_csv

__all__ = ["load_csv", "save_csv"]

#: Imported on first use (``creep_online.io.open_source``); pyserial/python-can load only when a source opens.
_LAZY = {"open_source": "registry", "register_source": "registry", "available_sources": "registry",
         "Sample": "sources", "SourceStats": "sources", "SampleSource": "sources",
         "ReconnectingSource": "sources", "Option": "source_options", "FeedLoop": "feed"}


def __getattr__(name: str):
    """The source API on first use, so ``import creep_online.io`` stays light."""
    if name == "TransportError":
        from ..errors import TransportError
        return TransportError
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
