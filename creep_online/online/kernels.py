"""The exact model coefficients and state step of the online code, at the import path the simulated plants
use (``hil_sim.varying_plant``): ``creep_online.online._kernels.coefficients``, re-exported here."""
from ._kernels.coefficients import (advance_state, coefficient_sums, model_coefficients, model_values,  # noqa: F401
                                    node_coefficients, node_history, truncated_gl_block)
