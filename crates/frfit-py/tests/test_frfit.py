"""Tests of the Python package: arrays in, models out, against exact truths built here
with NumPy (modal plants whose poles and residues are known), round trips through files,
python-control and scikit-rf objects, and errors as exceptions."""

import math
import threading
import time

import numpy as np
import pytest

import frfit

TAU = 2.0 * math.pi

# The truth: a 2 x 3 plant with four lightly damped modes of real mode shapes (the
# residue of a displacement FRF, phi psi^T / (2 j w_d), rank one).
MODES_HZ = np.array([48.0, 123.0, 261.0, 407.0])
ZETAS = np.array([0.012, 0.02, 0.008, 0.015])


def _residues(rng, ny=2, nu=3, complex_shapes=False):
    out = []
    for f in MODES_HZ:
        c = rng.normal(size=ny) + (0.3j * rng.normal(size=ny) if complex_shapes else 0)
        b = rng.normal(size=nu) + (0.3j * rng.normal(size=nu) if complex_shapes else 0)
        out.append(np.outer(c, b) / (2j * TAU * f) * 1e3)
    return out


def _poles():
    w = TAU * MODES_HZ
    return -ZETAS * w + 1j * w * np.sqrt(1.0 - ZETAS**2)


def plant(freq_hz, seed=3, delay_s=0.0, complex_shapes=False):
    """The exact response (n, 2, 3) of the modal plant at freq_hz."""
    rng = np.random.default_rng(seed)
    s = 1j * TAU * np.asarray(freq_hz)
    g = np.zeros((len(s), 2, 3), dtype=complex)
    for p, r in zip(_poles(), _residues(rng, complex_shapes=complex_shapes)):
        g += r[None] / (s[:, None, None] - p) + r.conj()[None] / (s[:, None, None] - p.conj())
    return g * np.exp(-s * delay_s)[:, None, None]


def noisy(freq_hz, rel=1e-4, seed=11, delay_s=0.0):
    """Noisy data with the exact variance of its noise, and the noiseless truth."""
    g0 = plant(freq_hz, delay_s=delay_s)
    rng = np.random.default_rng(seed)
    sigma = rel * np.median(np.abs(g0)) * np.ones(g0.shape)
    e = (rng.normal(size=g0.shape) + 1j * rng.normal(size=g0.shape)) * sigma / math.sqrt(2)
    return frfit.FrfData(freq_hz, g0 + e, var=sigma**2, units="m/N"), g0


FREQ = np.linspace(10.0, 600.0, 1200)


def rel_err(a, b):
    return float(np.median(np.abs(a - b) / np.abs(b)))


def test_noise_free_arrays_are_recovered_to_near_machine_precision():
    data = frfit.FrfData(FREQ, plant(FREQ))
    model = frfit.fit(data, delay="none")
    f = np.array([m.f_hz for m in model.modes])
    z = np.array([m.zeta for m in model.modes])
    assert len(f) == len(MODES_HZ), model.modes
    assert np.max(np.abs(f - MODES_HZ) / MODES_HZ) < 1e-9
    assert np.max(np.abs(z - ZETAS) / ZETAS) < 1e-7
    assert rel_err(model.response(FREQ), plant(FREQ)) < 1e-9
    assert model.converged, model.convergence


def test_noisy_arrays_fit_at_the_noise_level_with_uncertainty_from_ml():
    data, g0 = noisy(FREQ)
    model = frfit.fit(data, delay="none", refine="ml")
    assert len(model.modes) == len(MODES_HZ)
    for m, f, z in zip(model.modes, MODES_HZ, ZETAS):
        assert m.f_hz_std is not None and m.zeta_std is not None
        # within 5 standard deviations of the truth (the truth is exact here)
        assert abs(m.f_hz - f) < 5 * m.f_hz_std + 1e-12, m
        assert abs(m.zeta - z) < 5 * m.zeta_std + 1e-12, m
    # the model is closer to the truth than the data are
    assert rel_err(model.response(FREQ), g0) < 0.5 * rel_err(data.G, g0)
    s = model.summary
    assert s["command"] == "fit" and s["data"]["ny"] == 2 and s["data"]["nu"] == 3


def test_the_data_keep_their_layout_and_survive_a_csv_round_trip(tmp_path):
    data, _ = noisy(FREQ)
    g = data.G
    assert g.shape == (len(FREQ), 2, 3) and data.ny == 2 and data.nu == 3 and len(data) == len(FREQ)
    # entry (i, j) of line k is G[k, i, j]: compare with the truth entry by entry
    g0 = plant(FREQ)
    assert abs(g[5, 1, 2] - g0[5, 1, 2]) < 1e-2 * abs(g0[5, 1, 2])
    path = tmp_path / "frf.csv"
    data.save(path)
    back = frfit.read(path)
    np.testing.assert_array_equal(back.freq_hz, data.freq_hz)
    np.testing.assert_array_equal(back.G, data.G)
    np.testing.assert_array_equal(back.var, data.var)
    assert back.units == "m/N"
    assert back.source == str(path)


def test_a_siso_frf_can_be_given_as_a_vector():
    g = plant(FREQ)[:, 0, 0]
    data = frfit.FrfData(FREQ, g)
    assert (data.ny, data.nu) == (1, 1)
    np.testing.assert_array_equal(data.G[:, 0, 0], g)


def test_the_model_file_round_trips(tmp_path):
    data = frfit.FrfData(FREQ, plant(FREQ))
    model = frfit.fit(data, delay="none")
    path = tmp_path / "model.json"
    model.save(path)
    back = frfit.load_model(path)
    np.testing.assert_allclose(back.response(FREQ), model.response(FREQ), rtol=1e-12)
    assert back.summary is None and model.summary is not None
    assert '"frfit-additive-model"' in model.to_json()


def _control_response(sys, freq_hz):
    """python-control's response (n, ny, nu) at freq_hz, continuous or discrete."""
    w = TAU * np.asarray(freq_hz)
    x = np.exp(1j * w * sys.dt) if sys.dt else 1j * w
    r = np.asarray(sys(x, squeeze=False))  # (ny, nu, n)
    return np.transpose(r, (2, 0, 1))


def test_to_control_equals_the_model_response_continuous_with_delay():
    control = pytest.importorskip("control")
    data = frfit.FrfData(FREQ, plant(FREQ, delay_s=3e-4))
    # a declared delay (the estimate of a free delay is checked by the Rust tests)
    model = frfit.fit(data, delay="300us")
    assert model.delay_s == pytest.approx(3e-4, rel=1e-12) and not model.delay_fitted
    with pytest.warns(UserWarning, match="delay"):
        sys = model.to_control()
    assert isinstance(sys, control.StateSpace) and not sys.dt
    w = TAU * FREQ
    h = _control_response(sys, FREQ) * np.exp(-1j * w * sys.delay_s)[:, None, None]
    m = model.response(FREQ)
    assert np.max(np.abs(h - m)) < 1e-9 * np.max(np.abs(m))


def test_to_control_is_discrete_for_a_model_with_the_exact_hold():
    pytest.importorskip("control")
    data = frfit.FrfData(FREQ, plant(FREQ))
    model = frfit.fit(data, hold="zoh:5000", delay="none")
    assert model.hold.startswith("zoh:5000")
    sys = model.to_control(warn=False)
    assert sys.dt == pytest.approx(2e-4)
    w = TAU * FREQ
    h = _control_response(sys, FREQ) * np.exp(-1j * w * sys.delay_s)[:, None, None]
    m = model.response(FREQ)
    assert np.max(np.abs(h - m)) < 1e-9 * np.max(np.abs(m))
    ss = model.state_space()
    assert ss.dt == pytest.approx(2e-4) and ss.discrete is not None
    assert ss.A.shape == (ss.n_states, ss.n_states) and ss.B.shape == (ss.n_states, 3)
    assert ss.C.shape == (2, ss.n_states) and ss.D.shape == (2, 3)


def test_from_control_and_from_network_read_the_peers_objects():
    control = pytest.importorskip("control")
    g = plant(FREQ)
    frd = control.frd(np.transpose(g, (1, 2, 0)), TAU * FREQ)
    data = frfit.FrfData.from_control(frd)
    np.testing.assert_allclose(data.freq_hz, FREQ, rtol=1e-15)
    np.testing.assert_array_equal(data.G, g)
    skrf = pytest.importorskip("skrf")
    sq = plant(FREQ)[:, :, :2]  # a square 2-port
    ntwk = skrf.Network(frequency=skrf.Frequency.from_f(FREQ, unit="hz"), s=sq)
    net = frfit.FrfData.from_network(ntwk)
    np.testing.assert_allclose(net.freq_hz, FREQ, rtol=1e-12)
    np.testing.assert_array_equal(net.G, sq)
    with pytest.raises(frfit.FrfitError, match="param"):
        frfit.FrfData.from_network(ntwk, param="q")


def test_errors_are_exceptions_that_name_what_is_wrong(tmp_path):
    g = plant(FREQ)
    with pytest.raises(frfit.FrfitError, match="freq_hz has"):
        frfit.FrfData(FREQ[:-1], g)
    with pytest.raises(frfit.FrfitError, match="strictly increasing"):
        frfit.FrfData(FREQ[::-1], g)
    with pytest.raises(frfit.FrfitError, match="shape"):
        frfit.FrfData(FREQ, g, var=np.ones((len(FREQ), 3, 2)))
    with pytest.raises(frfit.FrfitError, match="non-finite"):
        bad = g.copy()
        bad[3, 0, 0] = np.nan
        frfit.FrfData(FREQ, bad)
    with pytest.raises(frfit.FrfitError, match="no such file"):
        frfit.read(tmp_path / "missing.csv")
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("freq_hz,G1_1_re,G1_1_im\n1.0,2.0,x\n")
    with pytest.raises(frfit.FrfitError, match=r"bad.csv:2: column G1_1_im"):
        frfit.read(bad_csv)
    data = frfit.FrfData(FREQ, g)
    with pytest.raises(frfit.FrfitError, match="hold"):
        frfit.fit(data, hold="foh:100")
    with pytest.raises(frfit.FrfitError, match="_var"):
        frfit.fit(data, weighting="variance")
    with pytest.raises(frfit.FrfitError, match="band"):
        frfit.fit(data, band=(3000, 4000))
    with pytest.raises(frfit.FrfitError, match="delay"):
        frfit.fit(data, delay="-3")
    assert issubclass(frfit.FrfitError, ValueError)


def _multisine(fs, n, bins, rng):
    """One period of a random-phase multisine exciting `bins`."""
    spec = np.zeros(n // 2 + 1, dtype=complex)
    spec[bins] = np.exp(2j * math.pi * rng.random(len(bins)))
    return np.fft.irfft(spec, n) * n


def test_nonparametric_recovers_the_frf_from_time_records():
    fs, n, periods = 2000.0, 1000, 4
    bins = np.arange(10, 300, 3)
    rng = np.random.default_rng(5)
    f = bins * fs / n
    g = plant(f)  # (lines, 2, 3)
    # three experiments of three inputs, each input its own multisine
    u = np.zeros((n, 3, 3, periods))
    y = np.zeros((n, 2, 3, periods))
    for e in range(3):
        us = np.stack([_multisine(fs, n, bins, rng) for _ in range(3)], axis=1)  # (n, 3)
        uf = np.fft.rfft(us, axis=0)
        yf = np.zeros((n // 2 + 1, 2), dtype=complex)
        yf[bins] = np.einsum("kij,kj->ki", g, uf[bins])
        ys = np.fft.irfft(yf, n, axis=0)
        for p in range(periods):
            u[:, :, e, p] = us
            y[:, :, e, p] = ys + 1e-6 * rng.normal(size=ys.shape)
    est = frfit.nonparametric(u, y, fs=fs)
    np.testing.assert_allclose(est.freq_hz, f, rtol=1e-12)
    assert est.G.shape == (len(bins), 2, 3)
    assert rel_err(est.G, g) < 1e-4
    assert est.var is not None
    # the given lines give the same estimate
    est2 = frfit.nonparametric(u, y, fs=fs, lines=list(bins))
    np.testing.assert_allclose(est2.G, est.G, rtol=1e-12)
    with pytest.raises(frfit.FrfitError, match="--lines"):
        frfit.nonparametric(u, y, fs=fs, lines=[0, 5])


def test_diagnose_finds_an_undeclared_delay_and_reports_its_steps(tmp_path):
    data, g0 = noisy(FREQ, delay_s=8e-5)
    d = frfit.diagnose(data)
    accepted = [s for s in d.steps if s.accepted]
    assert any(s.effect == "delay" for s in accepted), d.steps
    step = next(s for s in accepted if s.effect == "delay")
    assert step.after.median_rel < step.before.median_rel
    assert abs(step.params["seconds"] - 8e-5) < 1e-6, step.params
    assert d.verdict == "noise_limited", d.verdict_evidence
    assert rel_err(d.model.response(FREQ), g0) < 1e-4
    assert d.final_errors.median_rel < 1e-3 < d.initial_errors.median_rel
    d.report(tmp_path / "rep")
    assert (tmp_path / "rep" / "report.md").exists()
    assert (tmp_path / "rep" / "summary.json").exists()
    assert (tmp_path / "rep" / "model.json").exists()


def test_validate_and_reduce():
    data, _ = noisy(FREQ)
    model = frfit.fit(data, delay="none")
    other, _ = noisy(FREQ, seed=99)
    v = frfit.validate(model, other)
    assert v.not_invalidated, v
    assert v.gamma.shape == (len(FREQ),) and v.gamma_max >= 0.0
    r = frfit.reduce(model)
    assert len(r.hankel_singular_values) == r.stable_order
    assert np.all(np.diff(r.bounds) <= 0)
    # the three strongest modes and the rigid-body states
    small = frfit.reduce(model, order=r.rigid_order + 6)
    assert small.model is not None and len(small.model.modes) == 3
    assert small.measured_error <= small.error_bound * (1 + 1e-9)
    with pytest.raises(frfit.FrfitError, match="order"):
        frfit.reduce(model, order=10_000)


def test_validate_with_the_models_own_uncertainty():
    # fitted at 1e-2 noise, validated on a measurement 100 times quieter: the data
    # alone invalidate the estimate; its own uncertainty (from the fit data) explains it
    data, _ = noisy(FREQ, rel=1e-2, seed=5)
    model = frfit.fit(data, delay="none")
    quiet, _ = noisy(FREQ, rel=1e-4, seed=6)
    plain = frfit.validate(model, quiet)
    assert not plain.not_invalidated, plain
    assert plain.beyond_model_uncertainty is None and plain.model_bound is None
    v = frfit.validate(model, quiet, fit_data=data)
    b = v.beyond_model_uncertainty
    assert b["verdict"] == "not_invalidated", b
    assert b["model_to_disturbance_median"] > 1.0, b
    assert v.verdict == plain.verdict
    assert v.model_bound.shape == (len(FREQ),)
    assert np.all(v.gamma_beyond_model <= v.gamma * (1 + 1e-12))


def test_the_gil_is_released_during_a_fit():
    data, _ = noisy(np.linspace(10.0, 600.0, 4000))
    ticks = 0
    done = threading.Event()

    def work():
        for _ in range(3):
            frfit.fit(data, delay="none", refine="ml")
        done.set()

    t = threading.Thread(target=work)
    t0 = time.perf_counter()
    t.start()
    while not done.is_set():
        ticks += 1
        time.sleep(0.002)
    t.join()
    elapsed = time.perf_counter() - t0
    # the main thread ran all along (about one tick per 2 ms of the fit when a core is
    # free; the fit's threads take both cores, so allow for slow wake-ups): a held GIL
    # would leave it one tick
    assert ticks >= 10 and ticks > 0.05 * elapsed / 0.002, (ticks, elapsed)


def test_diagnose_starts_where_fit_ends_on_complex_mode_shapes():
    # residues c b^T with strongly complex c and b (seed 3), not scaled by 1 / (2 j w_d)
    rng = np.random.default_rng(3)
    s = 1j * TAU * FREQ
    g0 = np.zeros((len(s), 2, 3), dtype=complex)
    for p in _poles():
        c = rng.normal(size=2) + 0.3j * rng.normal(size=2)
        b = rng.normal(size=3) + 0.3j * rng.normal(size=3)
        r = np.outer(c, b) * 2e3
        g0 += r[None] / (s[:, None, None] - p) + r.conj()[None] / (s[:, None, None] - p.conj())
    rng = np.random.default_rng(11)
    sigma = 1e-4 * np.median(np.abs(g0)) * np.ones(g0.shape)
    e = (rng.normal(size=g0.shape) + 1j * rng.normal(size=g0.shape)) * sigma / math.sqrt(2)
    data = frfit.FrfData(FREQ, g0 + e, var=sigma**2)
    fitted = frfit.fit(data, delay="none")
    assert rel_err(fitted.response(FREQ), g0) < 1e-4
    d = frfit.diagnose(data)
    # the CMIF -> refined-IV first fit of `diagnose` ends at 100 % error with 3 of 4 modes
    # here; the diagnosis from it ends worse than `fit`, so it runs again from `fit`'s
    # model (issues 41, 42), which `fit` reaches through its SK second start
    assert d.initial_errors.median_rel <= 1.02 * rel_err(fitted.response(FREQ), data.G)
    assert rel_err(d.model.response(FREQ), g0) < 1e-4
    assert "from_fit" in d.summary["initial"], d.summary["initial"].keys()
    for step in d.steps:
        assert step.held_out is None or len(step.held_out) == 2


def test_the_simulator_truth_is_recovered_and_the_example_runs():
    import importlib.util
    import pathlib

    control = pytest.importorskip("control")
    path = pathlib.Path(__file__).parent.parent / "examples" / "fit_from_arrays.py"
    spec = importlib.util.spec_from_file_location("fit_from_arrays", path)
    ex = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ex)
    model, sys, diff = ex.main()
    assert isinstance(sys, control.StateSpace)
    assert diff < 1e-9
    assert len(model.modes) == 17
    assert all(m.f_hz_std is not None and m.f_hz_std > 0 for m in model.modes)


def test_realizations_separate_the_nonlinear_distortion_from_the_noise(tmp_path):
    # 2 realizations x 3 experiments of a 3-input system, 4 periods each; a static cubic
    # term on the outputs makes a stochastic nonlinear contribution that is periodic (the
    # period spread cannot see it) but changes with the random phases
    fs = 2000.0
    u, y = _records(8, experiments=6, noise=1e-5, cubic=0.02)
    est = frfit.nonparametric(u, y, fs=fs)
    assert est.metadata["realizations"] == "2"
    assert est.var_noise is not None and est.var is not None
    ratio = np.median(est.var / est.var_noise)
    assert ratio > 10, ratio  # the distortion is far above the noise
    d = est.distortion
    assert d["total_to_noise"] == pytest.approx(ratio, rel=0.05)
    assert d["nonlinear_db"] > d["noise_db"] + 10
    # one realization: the variance is the noise variance only, and there is no noise part
    one = frfit.nonparametric(u, y, fs=fs, realizations=1)
    assert one.var_noise is None and np.median(one.var / est.var_noise) < 3
    # the CSV keeps both variances
    path = tmp_path / "bla.csv"
    est.save(path)
    back = frfit.read(path)
    np.testing.assert_array_equal(back.var_noise, est.var_noise)
    np.testing.assert_array_equal(back.var, est.var)
    with pytest.raises(frfit.FrfitError, match="full rank"):
        frfit.nonparametric(u, y, fs=fs, realizations=3)


def _records(seed, experiments=3, periods=4, noise=1e-3, fs=2000.0, n=1000, cubic=0.0):
    """Periodic multisine records of the plant: u (n, 3, E, P), y (n, 2, E, P); `cubic`
    adds a static cubic term to the outputs (a stochastic nonlinear contribution)."""
    bins = np.arange(10, 300, 3)
    rng = np.random.default_rng(seed)
    g = plant(bins * fs / n)
    u = np.zeros((n, 3, experiments, periods))
    y = np.zeros((n, 2, experiments, periods))
    for e in range(experiments):
        us = np.stack([_multisine(fs, n, bins, rng) for _ in range(3)], axis=1)
        uf = np.fft.rfft(us, axis=0)
        yf = np.zeros((n // 2 + 1, 2), dtype=complex)
        yf[bins] = np.einsum("kij,kj->ki", g, uf[bins])
        ys = np.fft.irfft(yf, n, axis=0)
        ys = ys + cubic * ys**3 / np.std(ys) ** 2
        for p in range(periods):
            u[:, :, e, p] = us
            y[:, :, e, p] = ys + noise * np.std(ys) * rng.normal(size=ys.shape)
    return u, y


def test_predict_scores_a_model_on_test_records_against_their_noise_floor(tmp_path):
    u, y = _records(1)
    est = frfit.nonparametric(u, y, fs=2000.0)
    model = frfit.fit(est, delay="none")
    ut, yt = _records(2)  # new random phases, new noise: records the model never saw
    p = frfit.predict(model, ut, yt, fs=2000.0)
    assert p.records == 3 and p.nrmse.shape == (2,)
    # the model predicts at the records' noise floor (its own error is far below it)
    assert np.all(p.nrmse < 1.5 * p.noise_floor), (p.nrmse, p.noise_floor)
    assert np.all(p.noise_floor < 1e-2)
    # a model that lacks a mode predicts far worse
    small = frfit.reduce(model, order=model.order - 2).model
    worse = frfit.predict(small, ut, yt, fs=2000.0)
    assert np.all(worse.nrmse > 3 * p.nrmse), (worse.nrmse, p.nrmse)
    p.report(tmp_path / "pred")
    assert (tmp_path / "pred" / "prediction.json").exists()
    assert (tmp_path / "pred" / "prediction.svg").exists()


def test_diagnose_predicts_test_records_with_the_initial_and_the_final_model(tmp_path):
    u, y = _records(1)
    est = frfit.nonparametric(u, y, fs=2000.0)
    ut, yt = _records(2)  # records the diagnosis never saw
    d = frfit.diagnose(est, fs=2000.0, test_records=(ut, yt))
    initial, final = d.test_predictions
    assert final.records == 3 and final.nrmse.shape == (2,)
    # both models predict at the records' noise floor: nothing was missing
    assert np.all(final.nrmse < 1.5 * final.noise_floor), (final.nrmse, final.noise_floor)
    assert np.all(initial.nrmse < 1.5 * initial.noise_floor), initial.nrmse
    # the same numbers as frfit.predict with each model
    p = frfit.predict(d.model, ut, yt, fs=2000.0)
    np.testing.assert_allclose(p.nrmse, final.nrmse, rtol=1e-12)
    q = frfit.predict(d.initial_model, ut, yt, fs=2000.0)
    np.testing.assert_allclose(q.nrmse, initial.nrmse, rtol=1e-12)
    d.report(tmp_path / "rep")
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "## Prediction of test records" in md
    for which in ["initial", "final"]:
        assert (tmp_path / "rep" / "test_records" / which / "prediction.json").exists()
    assert frfit.diagnose(est, fs=2000.0).test_predictions is None
    # records of another plant's shape are an error before the diagnosis runs
    with pytest.raises(frfit.FrfitError):
        frfit.diagnose(est, fs=2000.0, test_records=(ut, yt[:, :1]))


def _frfit_binary():
    import pathlib

    exe = pathlib.Path(__file__).resolve().parents[3] / "target" / "release" / "frfit"
    if not exe.exists():
        pytest.skip(f"skipped: the frfit binary is not built ({exe}); cargo build --release")
    return exe


@pytest.mark.parametrize("how", ["savez", "savez_compressed", "npy"])
def test_the_cli_reads_numpy_time_records_as_numpy_writes_them(tmp_path, how):
    import subprocess

    exe = _frfit_binary()
    u, y = _records(4, experiments=6)  # 2 realizations of 3 experiments
    if how == "npy":
        np.save(tmp_path / "u.npy", u)
        np.save(tmp_path / "y.npy", np.asfortranarray(y))  # Fortran order too
        files = [str(tmp_path / "u.npy"), str(tmp_path / "y.npy")]
    else:
        getattr(np, how)(tmp_path / "rec.npz", u=u, y=y)
        files = [str(tmp_path / "rec.npz")]
    out = tmp_path / "frf.csv"
    subprocess.run(
        [str(exe), "--quiet", "nonparametric", *files, "--fs", "2000", "--out", str(out)],
        check=True,
    )
    cli = frfit.read(out)
    arrays = frfit.nonparametric(u, y, fs=2000.0)
    np.testing.assert_array_equal(cli.freq_hz, arrays.freq_hz)
    np.testing.assert_allclose(cli.G, arrays.G, rtol=1e-12)
    assert cli.var_noise is not None and cli.metadata["realizations"] == "2"
    bad = subprocess.run(
        [str(exe), "nonparametric", *files, "--fs", "2000", "--realizations", "4",
         "--out", str(out)],
        capture_output=True, text=True,
    )
    assert bad.returncode != 0 and "--realizations" in bad.stderr
