"""Fit a wafer-stage-like FRF given as NumPy arrays, print the modes with their standard
deviations, and hand the model to python-control.

The data: a 4 x 13 plant with a free rigid body and 17 lightly damped modes, 4000 lines
from 20 to 2000 Hz, noise 1e-3 of the median magnitude with its variance (frfit's own
simulator, so that the truth is known; any arrays of the same shapes will do).

    python examples/fit_from_arrays.py
"""

import time

import numpy as np

import frfit


def main():
    measured, noiseless, truth = frfit.simulate_random_modal(
        ny=4, nu=13, modes=17, lines=4000, band=(20.0, 2000.0), noise=1e-3,
        rigid_body=True, seed=1,
    )
    # the arrays a user has: frequencies (Hz), G (n, ny, nu) complex, the variance
    freq_hz, G, var = measured.freq_hz, measured.G, measured.var
    data = frfit.FrfData(freq_hz, G, var=var, units="m/N")

    t0 = time.perf_counter()
    model = frfit.fit(data, refine="ml")
    print(f"fit: {time.perf_counter() - t0:.2f} s, {model}")

    print("     f [Hz]    +- 1 sigma        zeta    +- 1 sigma    truth f [Hz]")
    true_f = sorted(m["f_hz"] for m in truth["model"]["modes"])
    for m in model.modes:
        nearest = min(true_f, key=lambda f: abs(f - m.f_hz))
        print(f"  {m.f_hz:10.4f}  {m.f_hz_std:10.2e}  {m.zeta:10.6f}  {m.zeta_std:10.2e}  {nearest:12.4f}")

    err = np.median(np.abs(model.response(freq_hz) - noiseless.G) / np.abs(noiseless.G))
    print(f"median relative error against the noiseless truth: {err:.2e}")

    sys = model.to_control(warn=False)  # python-control StateSpace; the delay beside it
    w = 2 * np.pi * freq_hz
    x = np.exp(1j * w * sys.dt) if sys.dt else 1j * w
    h = np.transpose(np.asarray(sys(x, squeeze=False)), (2, 0, 1))
    h = h * np.exp(-1j * w * sys.delay_s)[:, None, None]
    H = model.response(freq_hz)
    diff = np.max(np.abs(h - H)) / np.max(np.abs(H))
    print(f"python-control StateSpace ({sys.nstates} states, delay {sys.delay_s:.3e} s) "
          f"against Model.response: max relative difference {diff:.1e}")
    return model, sys, diff


if __name__ == "__main__":
    main()
