"""frfit: frequency-domain identification of lightly damped MIMO motion systems.

Measured frequency response functions (FRFs) in; a compact, physically meaningful,
validated continuous-time model out (the additive modal model of the wafer-stage
paper, fitted by refined instrumental variables at the measurement's noise floor),
with the uncertainty of its modes and a diagnosis of what the model still misses.

The same implementation as the ``frfit`` command line, on NumPy arrays::

    import frfit
    data = frfit.read("DATA.csv")            # or frfit.FrfData(freq_hz, G, var=...)
    model = frfit.fit(data, band=(20, 2000), hold="zoh:10000")
    for m in model.modes:
        print(m.f_hz, m.f_hz_std, m.zeta, m.zeta_std)
    H = model.response(data.freq_hz)          # complex (n, ny, nu)
    sys = model.to_control()                  # python-control StateSpace; sys.delay_s

Arrays: an FRF ``G`` is shaped ``(n_lines, ny, nu)``; time records ``(n_samples,
channels[, experiments[, periods]])``. Errors raise :class:`FrfitError` (a
``ValueError``) with the command line's message, naming the file, line, column or
option. The GIL is released while frfit computes.
"""

from ._frfit import (
    Diagnosis,
    ErrorStats,
    FrfData,
    FrfitError,
    Mode,
    Model,
    Reduction,
    StateSpace,
    Step,
    Validation,
    __version__,
    diagnose,
    fit,
    load_model,
    nonparametric,
    predict,
    Prediction,
    read,
    reduce,
    simulate_random_modal,
    validate,
)

__all__ = [
    "Diagnosis",
    "ErrorStats",
    "FrfData",
    "FrfitError",
    "Mode",
    "Model",
    "Reduction",
    "StateSpace",
    "Step",
    "Validation",
    "__version__",
    "diagnose",
    "fit",
    "load_model",
    "nonparametric",
    "predict",
    "Prediction",
    "read",
    "reduce",
    "simulate_random_modal",
    "validate",
]
