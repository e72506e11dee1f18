"""creep_online: identify the fractional-order creep model G(s) = b / (s^alpha (1 + a1 s + a2 s^2)).

Core (numpy/scipy/numba only): the model, exact and paper-faithful simulators,
two-layer batch identification and the online estimator. Hardware transports
and plots are optional extras.
"""
import os

# The matrices here are tiny (2x2 to 10x10); multi-threaded BLAS only adds
# synchronisation (measured: identification 13x slower on 2 cores). Respect a
# user's explicit setting.
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
# With colorama installed (the docs extra brings it), numba colours its messages and colorama writes a
# terminal reset at exit: stray bytes after a command's output (`--json` on a terminal is then not JSON).
os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")

# Before numba is imported: a read-only install caches kernels in a per-user directory.
from ._lazy import lazy_attributes as _lazy_attributes
from ._numba_cache import configure as _configure_numba_cache

_configure_numba_cache()

from .errors import CreepOnlineError, DataError, IdentificationError, ModelError, OutputError
from .model import CreepModel, ExtendedModel, FittedModel
from .record import Record
from .simulate import simulate, step_response  # light: the module loads numba and scipy on first call

__version__ = "0.1.0"

__all__ = [
    "CreepModel", "ExtendedModel", "FittedModel", "Record", "simulate", "step_response", "identify",
    "OnlineEstimator", "diagnose", "compare", "save_model", "load_model",
    "CreepOnlineError", "DataError", "IdentificationError", "ModelError", "OutputError",
]

# The API mirrors the CLI; the heavier layers load on first use, not on import.
# identify loads scipy and numba (~1 s): the CLI's --help must not pay for them.
_LAZY = {"OnlineEstimator": "online", "diagnose": "diagnostics", "identify": "identification",
         "compare": "diagnostics.compare", "save_model": "io.model_file", "load_model": "io.model_file"}
__getattr__ = _lazy_attributes(__name__, _LAZY)
