"""Model discrepancy (docs/diagnostics.md): compare, locate where the model fails, explain which effect is missing, extend.

``compare(model, record)`` gives a model's fit percent and residual on a record;
``diagnose(record_or_t_u_y)`` runs the whole workflow and returns a
``Diagnosis`` (``.verdict``, ``.candidates``, ``.to_dict()`` = the
``creep-online diagnose --json`` schema). ``fit_extended`` / ``with_effects``
fit and build models with one or more catalogue effects.
"""
from .._lazy import lazy_attributes

#: Imported on first use (scipy and the fitting kernels load only when a diagnosis or a fit runs: the CLI's
#: ``compare --help`` needs none of them).
_LAZY = {
    **dict.fromkeys(("Comparison", "compare", "error_metrics", "overlay"), "compare"),
    **dict.fromkeys(("Candidate", "Diagnosis", "diagnose", "evidence"), "explain"),
    **dict.fromkeys(("ExtendedFit", "ExtendedModel", "Prepared", "check_effects", "fit_base", "fit_extended",
                     "prepare", "refit", "with_effects"), "extended"),
    **dict.fromkeys(("locate", "spectrum_peaks"), "locate"),
    **dict.fromkeys(("autocorrelation", "cross_correlation", "parameter_uncertainty"), "residuals"),
}

__all__ = [
    "diagnose", "Diagnosis", "Candidate", "evidence",
    "compare", "Comparison", "error_metrics", "overlay",
    "prepare", "Prepared", "fit_base", "fit_extended", "ExtendedFit", "ExtendedModel", "with_effects", "refit",
    "check_effects", "locate", "spectrum_peaks", "autocorrelation", "cross_correlation", "parameter_uncertainty",
]

__getattr__ = lazy_attributes(__name__, _LAZY)
