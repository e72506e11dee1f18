"""creep_online: identify the fractional-order creep model G(s) = b / (s^alpha (1 + a1 s + a2 s^2)).

Core (numpy/scipy/numba only): the model, exact and paper-faithful simulators,
two-layer batch identification and the online estimator. Hardware transports
and plots are optional extras.
"""
import os
import sys


def _guard_cli_start() -> None:
    """In the ``creep-online`` program only: a Ctrl-C while the package still loads (before ``cli.main`` takes
    the signals over) ends it with one line and status 130, not a KeyboardInterrupt traceback. It runs before
    any import of the package (os and sys are loaded with the interpreter), so that the window where Python's
    own traceback can show is as short as it can be; a library user's process (any other program) is left alone."""
    argv0 = os.path.basename(sys.argv[0]) if sys.argv else ""
    orig = list(getattr(sys, "orig_argv", []))
    as_module = any(a == "-m" and b == "creep_online" for a, b in zip(orig, orig[1:]))
    if argv0 not in ("creep-online", "creep-online.exe") and not as_module:
        return
    previous = sys.excepthook

    def one_line(kind, value, tb) -> None:
        if issubclass(kind, KeyboardInterrupt):
            try:
                sys.stderr.write("creep-online: interrupted while starting\n")
                sys.stderr.flush()
            except Exception:  # noqa: BLE001 - a closed stderr: the status says it
                pass
            os._exit(130)           # 128 + SIGINT
        previous(kind, value, tb)
    sys.excepthook = one_line


_guard_cli_start()     # the creep-online program: Ctrl-C while this package loads is one line, never a traceback

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

from typing import TYPE_CHECKING

from .errors import CreepOnlineError, DataError, IdentificationError, ModelError, OutputError

if TYPE_CHECKING:  # for type checkers and editors; at run time these load on first use (below)
    from .diagnostics import diagnose
    from .diagnostics.compare import compare
    from .identification import identify
    from .io.model_file import load_model, save_model
    from .model import CreepModel, ExtendedModel, FittedModel
    from .online import OnlineEstimator
    from .record import Record
    from .simulate import simulate, step_response

__version__ = "0.1.0"

__all__ = [
    "CreepModel", "ExtendedModel", "FittedModel", "Record", "simulate", "step_response", "identify",
    "OnlineEstimator", "diagnose", "compare", "save_model", "load_model",
    "CreepOnlineError", "DataError", "IdentificationError", "ModelError", "OutputError",
]

# The API mirrors the CLI; everything but the errors loads on first use, not on import: numpy alone takes
# ~40 ms, identify's scipy and numba ~1 s, and the CLI's --help and --version need none of them.
_LAZY = {"CreepModel": "model", "ExtendedModel": "model", "FittedModel": "model", "Record": "record",
         "simulate": "simulate", "step_response": "simulate", "OnlineEstimator": "online",
         "diagnose": "diagnostics", "identify": "identification", "compare": "diagnostics.compare",
         "save_model": "io.model_file", "load_model": "io.model_file"}
__getattr__ = _lazy_attributes(__name__, _LAZY)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
