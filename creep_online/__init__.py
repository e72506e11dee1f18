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

from .errors import CreepOnlineError, DataError, IdentificationError, ModelError
from .model import CreepModel
from .record import Record
from .simulate import simulate, step_response

__version__ = "0.1.0"

__all__ = [
    "CreepModel", "Record", "simulate", "step_response",
    "CreepOnlineError", "DataError", "IdentificationError", "ModelError",
]
