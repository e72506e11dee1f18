"""Model discrepancy (docs/diagnostics.md): compare, locate where the model fails, explain which effect is missing, extend.

``compare(model, record)`` gives a model's fit percent and residual on a record;
``diagnose(record_or_t_u_y)`` runs the whole workflow and returns a
``Diagnosis`` (``.verdict``, ``.candidates``, ``.to_dict()`` = the
``creep-online diagnose --json`` schema). ``fit_extended`` / ``with_effects``
fit and build models with one or more catalogue effects.
"""
from .compare import Comparison, compare, error_metrics, overlay
from .explain import Candidate, Diagnosis, diagnose, evidence
from .extended import (ExtendedFit, ExtendedModel, Prepared, check_effects, fit_base, fit_extended, prepare, refit,
                       with_effects)
from .locate import locate, spectrum_peaks
from .residuals import autocorrelation, cross_correlation, parameter_uncertainty

__all__ = [
    "diagnose", "Diagnosis", "Candidate", "evidence",
    "compare", "Comparison", "error_metrics", "overlay",
    "prepare", "Prepared", "fit_base", "fit_extended", "ExtendedFit", "ExtendedModel", "with_effects", "refit",
    "check_effects", "locate", "spectrum_peaks", "autocorrelation", "cross_correlation", "parameter_uncertainty",
]
