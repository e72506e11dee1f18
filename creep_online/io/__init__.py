"""Data in: files and live transports. Each source yields samples; nothing bad passes as good."""
from .._lazy import lazy_attributes
from ..errors import TransportError  # noqa: F401 - with the sources, as before (errors is light)
from .csvfile import load_csv, save_csv

__all__ = ["load_csv", "save_csv"]

#: Imported on first use (``creep_online.io.open_source``); pyserial/python-can load only when a source opens.
_LAZY = {"open_source": "registry", "register_source": "registry", "available_sources": "registry",
         "Sample": "sources", "SourceStats": "sources", "SampleSource": "sources",
         "ReconnectingSource": "sources", "Option": "source_options", "FeedLoop": "feed",
         "EstimatorListener": "can_listener", "CanSource": "can_source"}

__getattr__ = lazy_attributes(__name__, _LAZY)
