//! The signatures of the effects in the diagnosis loop's catalogue (DESIGN.md, "The
//! residual-diagnosis loop"): for each effect, the shape its omission leaves in the
//! residual `E = G - P`, fitted to the residual **without refitting the model**, so that
//! the loop can rank candidate effects before it spends a refit on one.
//!
//! | effect | residual when the model lacks it | template fitted here |
//! |---|---|---|
//! | delay `d` | `P (e^{-j w d} - 1) ~ -j w d P` | [`phase_trend`]: `d` by Gauss-Newton on the exact factor |
//! | zero-order hold at `fs` | `P (sinc(w / 2 fs) - 1) ~ -(w T)^2 / 24 P`, real and relative | [`hold_signature`]: amplitude of `-(w T)^2 / 24` |
//! | feedthrough `D` | `D`, constant over frequency | [`feedthrough_signature`]: a complex constant per entry |
//! | stiffness instead of a free rigid body | `P_rb (s^2 / (s^2 + 2 zeta w0 s + w0^2) - 1)`, `~ (w0 / w)^2 P_rb` | [`stiffness_signature`]: gain per entry, common `w0`, `zeta` |
//! | first-order actuator on input `j` | column `j`: `P_:j (1 / (1 + j w tau) - 1)` | [`io_factors`]: `tau` per column |
//! | first-order sensor on output `i` | row `i`: `P_i: (1 / (1 + j w tau) - 1)` | [`io_factors`]: `tau` per row |
//! | second-order (mount resonance) on a row or column | `P_i: (w0^2 / (s^2 + 2 zeta w0 s + w0^2) - 1)` | [`io_factors`]: `w0`, `zeta` per row and column |
//! | a factor common to every entry (amplifier bandwidth) | `P (h(j w) - 1)` | [`common_factor`]: first and second order |
//! | missed mode | a resonance `c b^T / (s^2 + 2 zeta w s + w^2)` | [`residual_peaks`]: CMIF peaks of the whitened residual |
//!
//! **Units and tests.** Every fit is a weighted least-squares fit with the inverse noise
//! variances as weights, so its *explained energy* `Delta` (the decrease of
//! `sum |E|^2 / var`) is in noise units. With the calibrated per-line scale `c` of the
//! residual's significance test ([`crate::residual`]), `Delta / c ~ chi2(p)` for `p`
//! fitted real parameters when the residual is noise; this gives the p-value. Because
//! `N m` is large, any structured residual makes the p-value tiny, so a signature is
//! **flagged** only when (1) the residual itself is significant, (2) the p-value is
//! below `alpha` (Bonferroni-corrected over rows or columns where the best of several
//! is taken) and (3) it explains at least [`crate::ResidualConfig::min_explained`] of
//! the *excess* energy (above the calibrated noise), so that an effect that explains a
//! sliver of another effect's residual is not flagged. Templates are evaluated on the
//! model's response `P` (noise-free), so `E / P` stands for the relative residual
//! `E / G` (equal to first order).

use crate::residual::{is_relative_peak, localized_regions, region_excess_fraction, Residual};
use crate::stats::chi2_sf;
use crate::ValidationError;
use frf_data::cmif::{cmif, pick_peaks};
use frf_data::{Frf, C64};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// The least-squares fit of an effect's template to the residual, in noise units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TemplateFit {
    /// `Delta`: decrease of `sum |E|^2 / var` when the fitted template is subtracted.
    pub explained: f64,
    /// Number of real parameters fitted.
    pub n_params: usize,
    /// Upper-tail p-value of `Delta / c` under `chi2(n_params)` (times the number of
    /// candidates when the best of several rows or columns is taken), at most 1.
    pub p_value: f64,
    /// `Delta` over the excess energy of the residual (energy above the calibrated
    /// noise), clamped to `[0, 1]`; 0 when there is no excess.
    pub explained_fraction: f64,
    /// Flagged: residual significant, `p_value < alpha`, `explained_fraction >=
    /// min_explained` (and any condition of the specific signature).
    pub significant: bool,
}

impl TemplateFit {
    fn new(res: &Residual, explained: f64, n_params: usize, n_candidates: usize) -> Self {
        let (c, _) = res.line_null();
        let explained = if explained.is_finite() {
            explained.max(0.0)
        } else {
            0.0
        };
        let p_value =
            (chi2_sf(explained / c, n_params.max(1) as f64) * n_candidates.max(1) as f64).min(1.0);
        let excess = res.excess_energy();
        let explained_fraction = if excess > 0.0 {
            (explained / excess).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let cfg = res.config();
        let significant = res.significance().significant
            && p_value < cfg.alpha
            && explained_fraction >= cfg.min_explained;
        Self {
            explained,
            n_params,
            p_value,
            explained_fraction,
            significant,
        }
    }
}

/// Per-line sums over a subset of entries: `A_k = sum_e |P|^2 / var`,
/// `B_k = sum_e conj(P) E / var` (a per-line factor `g_k` in `E ~ g_k P` then has the
/// weighted least-squares gain `2 Re(conj(g) B) - |g|^2 A`).
fn line_sums(res: &Residual, entries: impl Fn(usize) -> bool) -> (Vec<f64>, Vec<C64>) {
    let n = res.n_lines();
    let m = res.ny * res.nu;
    let sel: Vec<usize> = (0..m).filter(|e| entries(*e)).collect();
    let mut a = vec![0.0; n];
    let mut b = vec![C64::new(0.0, 0.0); n];
    for k in 0..n {
        let (mut ak, mut bk) = (0.0, C64::new(0.0, 0.0));
        for &e in &sel {
            let i = k * m + e;
            let p = res.model[i];
            let w = res.weight[i];
            ak += w * p.norm_sqr();
            bk += p.conj() * res.error[i] * w;
        }
        a[k] = ak;
        b[k] = bk;
    }
    (a, b)
}

/// A per-line factor `g(w; theta)` of the model: `E ~ g P`.
#[derive(Clone, Copy)]
enum Factor {
    /// `e^{-j w theta} - 1` (a delay `theta`).
    Delay,
    /// `1 / (1 + j w theta) - 1` (a first-order lag with time constant `theta`).
    FirstOrder,
}

impl Factor {
    fn g(self, w: f64, theta: f64) -> (C64, C64) {
        match self {
            Factor::Delay => {
                let ph = C64::from_polar(1.0, -w * theta);
                (ph - 1.0, C64::new(0.0, -w) * ph)
            }
            Factor::FirstOrder => {
                let d = C64::new(1.0, w * theta);
                let inv = d.inv();
                (inv - 1.0, C64::new(0.0, -w) * inv * inv)
            }
        }
    }
}

/// Result of [`fit_factor`]: `(theta, std, explained, linear theta)`.
struct FactorFit {
    theta: f64,
    std: f64,
    explained: f64,
    linear: f64,
}

/// Fits `theta` of a per-line factor to the per-line sums by Gauss-Newton from the
/// small-`theta` (linear, `g ~ -j w theta`) estimate, with step halving so that the
/// explained energy never decreases; stops when the step is below 1e-4 of the
/// statistical uncertainty. `std = sqrt(c / sum |g'|^2 A)`.
fn fit_factor(omega: &[f64], a: &[f64], b: &[C64], kind: Factor, c: f64) -> FactorFit {
    // Explained energy, gradient and Gauss-Newton curvature at theta, in one pass.
    let eval = |theta: f64| -> (f64, f64, f64) {
        let (mut v, mut gr, mut h) = (0.0, 0.0, 0.0);
        for (&w, (&ak, bk)) in omega.iter().zip(a.iter().zip(b)) {
            let (g, dg) = kind.g(w, theta);
            v += 2.0 * (g.conj() * bk).re - g.norm_sqr() * ak;
            gr += (dg.conj() * (bk - g * ak)).re;
            h += dg.norm_sqr() * ak;
        }
        (v, gr, h)
    };
    // Linear start: Re sum conj(-j w) B / sum w^2 A = -sum w Im B / sum w^2 A.
    let (mut num, mut den) = (0.0, 0.0);
    for (&w, (&ak, bk)) in omega.iter().zip(a.iter().zip(b)) {
        num -= w * bk.im;
        den += w * w * ak;
    }
    if !(den > 0.0 && den.is_finite() && num.is_finite()) {
        return FactorFit {
            theta: 0.0,
            std: f64::INFINITY,
            explained: 0.0,
            linear: 0.0,
        };
    }
    let linear = num / den;
    let mut theta = linear;
    let (mut best, mut gr, mut h) = eval(theta);
    for _ in 0..30 {
        if !(h > 0.0 && h.is_finite()) {
            break;
        }
        let tol = 1e-4 * (c / h).sqrt();
        let mut step = gr / h;
        let mut moved = false;
        for _ in 0..40 {
            let (v, g2, h2) = eval(theta + step);
            if v.is_finite() && v >= best {
                theta += step;
                (best, gr, h) = (v, g2, h2);
                moved = true;
                break;
            }
            step *= 0.5;
            if step.abs() <= tol {
                break;
            }
        }
        if !moved || step.abs() <= tol {
            break;
        }
    }
    FactorFit {
        theta,
        std: if h > 0.0 {
            (c / h).sqrt()
        } else {
            f64::INFINITY
        },
        explained: best.max(0.0),
        linear,
    }
}

/// The delay signature: the phase trend of the residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseTrend {
    /// The delay `d` (seconds) that the model lacks: `G ~ P e^{-j w d}`. Positive: the
    /// data lag the model (an uncompensated delay); negative: the model has too much
    /// delay (over-compensation).
    pub delay_s: f64,
    /// Standard error of `delay_s` (calibrated noise scale), seconds.
    #[serde(with = "crate::serde_f64")]
    pub std_s: f64,
    /// `delay_s / std_s`.
    #[serde(with = "crate::serde_f64")]
    pub z: f64,
    /// The small-delay (linear least-squares) estimate from `E ~ -j w d P`, the start of
    /// the Gauss-Newton refinement on the exact factor; biased low when `w d` reaches
    /// ~0.5 rad in the band.
    pub linear_delay_s: f64,
    /// The fit (1 parameter).
    pub fit: TemplateFit,
}

/// The phase trend of the residual: the delay `d` in `E = P (e^{-j w d} - 1)`, by
/// weighted least squares (weights `1 / var`), first linearised (`E ~ -j w d P`, i.e.
/// the least-squares slope of `Im(E / P)` against `-w` weighted by `|P|^2 / var`),
/// then refined by Gauss-Newton on the exact factor. The model's response `P` is the
/// regressor (noise-free). Flagged as described in the module documentation; its sign
/// says whether the model lacks delay (positive) or has too much (negative).
pub fn phase_trend(res: &Residual) -> PhaseTrend {
    let (a, b) = line_sums(res, |_| true);
    let (c, _) = res.line_null();
    let f = fit_factor(&res.omega, &a, &b, Factor::Delay, c);
    let fit = TemplateFit::new(res, f.explained, 1, 1);
    PhaseTrend {
        delay_s: f.theta,
        std_s: f.std,
        z: if f.std > 0.0 { f.theta / f.std } else { 0.0 },
        linear_delay_s: f.linear,
        fit,
    }
}

/// The zero-order-hold signature at a given sample rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HoldSignature {
    /// The sample rate tested, Hz.
    pub fs_hz: f64,
    /// Fitted amplitude `a` of the template `h(w) = -(w T)^2 / 24`, `T = 1 / fs`: 1 when
    /// the model lacks exactly the droop of a hold at `fs` (about 1.1 at a fifth of
    /// `fs` for a rigid-body-dominated plant, where the hold's aliasing adds to the
    /// droop).
    #[serde(with = "crate::serde_f64")]
    pub amplitude: f64,
    /// Standard error of `amplitude`.
    #[serde(with = "crate::serde_f64")]
    pub amplitude_std: f64,
    /// Weighted correlation (cosine, not centred) of `Re(E / P)` with `h(w)`, weights
    /// `|P|^2 / var`: 1 when the real relative residual has exactly the shape of the
    /// droop.
    pub correlation: f64,
    /// Share of the relative residual's energy in `Im(E / P)` (weights as above). A
    /// hold whose half-sample delay has been compensated leaves almost none; a delay
    /// leaves almost all.
    #[serde(with = "crate::serde_f64")]
    pub imag_fraction: f64,
    /// The sample rate the fitted droop corresponds to, `fs / sqrt(a)` (`None` for
    /// `a <= 0`).
    pub apparent_fs_hz: Option<f64>,
    /// The fit (1 parameter).
    pub fit: TemplateFit,
    /// Flagged and consistent with a hold at `fs`: `fit.significant`, correlation at
    /// least 0.9 and amplitude within `[0.5, 2]`.
    pub consistent: bool,
}

/// Tests the residual for an unmodelled zero-order hold at the sample rate `fs_hz`
/// without refitting: the residual of a hold the model lacks is
/// `E / P = sinc(w T / 2) - 1 ~ -(w T)^2 / 24` (real and relative; near Nyquist the
/// aliasing of the sampled plant adds to it), so this returns the correlation of
/// `Re(E / P)` with `-(w T)^2 / 24` and the fitted amplitude (1 for a hold at exactly
/// `fs`), with the explained energy and its test. A non-positive or non-finite
/// `fs_hz` gives an unflagged signature with NaN amplitude.
pub fn hold_signature(res: &Residual, fs_hz: f64) -> HoldSignature {
    let n = res.n_lines();
    let m = res.ny * res.nu;
    let (c, _) = res.line_null();
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        return HoldSignature {
            fs_hz,
            amplitude: f64::NAN,
            amplitude_std: f64::NAN,
            correlation: 0.0,
            imag_fraction: f64::NAN,
            apparent_fs_hz: None,
            fit: TemplateFit::new(res, 0.0, 1, 1),
            consistent: false,
        };
    }
    let t = 1.0 / fs_hz;
    let (mut shb, mut shha, mut sr, mut si) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..n {
        let wt = res.omega[k] * t;
        let h = -wt * wt / 24.0;
        for e in 0..m {
            let i = k * m + e;
            let p = res.model[i];
            let p2 = p.norm_sqr();
            if p2 <= 0.0 {
                continue;
            }
            let w = res.weight[i];
            let x = p.conj() * res.error[i]; // |P|^2 E / P
            shb += w * h * x.re;
            shha += w * h * h * p2;
            sr += w * x.re * x.re / p2;
            si += w * x.im * x.im / p2;
        }
    }
    let (amplitude, explained, std) = if shha > 0.0 {
        (shb / shha, shb * shb / shha, (c / shha).sqrt())
    } else {
        (f64::NAN, 0.0, f64::INFINITY)
    };
    let correlation = if shha > 0.0 && sr > 0.0 {
        shb / (shha * sr).sqrt()
    } else {
        0.0
    };
    let fit = TemplateFit::new(res, explained, 1, 1);
    let consistent = fit.significant && correlation >= 0.9 && (0.5..=2.0).contains(&amplitude);
    HoldSignature {
        fs_hz,
        amplitude,
        amplitude_std: std,
        correlation,
        imag_fraction: if sr + si > 0.0 {
            si / (sr + si)
        } else {
            f64::NAN
        },
        apparent_fs_hz: (amplitude > 0.0).then(|| fs_hz / amplitude.sqrt()),
        fit,
        consistent,
    }
}

/// The constant-feedthrough signature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeedthroughSignature {
    /// The fitted constant per entry, `vec` order (`d[j * ny + i]` for output `i`, input
    /// `j`).
    pub d: Vec<C64>,
    /// `sqrt(mean |d|^2)`.
    pub rms_magnitude: f64,
    /// `sum (Re d)^2 / sum |d|^2`: 1 for a real feedthrough (a phase rotation means a
    /// delay acts on the feedthrough differently from the model, e.g. half a sample
    /// after a hold's delay is compensated).
    pub real_fraction: f64,
    /// The fit (`2 ny nu` parameters).
    pub fit: TemplateFit,
}

/// Tests the residual for a constant (feedthrough / crosstalk) term: `E_ke ~ D_e`, a
/// complex constant per entry fitted by weighted least squares
/// (`D_e = sum_k E_ke / var_ke / sum_k 1 / var_ke`). A constant matters where the plant
/// has rolled off, so it shows at high frequencies in noise units.
pub fn feedthrough_signature(res: &Residual) -> FeedthroughSignature {
    let (n, m) = (res.n_lines(), res.ny * res.nu);
    let mut sw = vec![0.0; m];
    let mut se = vec![C64::new(0.0, 0.0); m];
    for k in 0..n {
        for e in 0..m {
            let i = k * m + e;
            sw[e] += res.weight[i];
            se[e] += res.error[i] * res.weight[i];
        }
    }
    let mut d = vec![C64::new(0.0, 0.0); m];
    let mut explained = 0.0;
    for e in 0..m {
        if sw[e] > 0.0 {
            d[e] = se[e] / sw[e];
            explained += se[e].norm_sqr() / sw[e];
        }
    }
    let s2: f64 = d.iter().map(|z| z.norm_sqr()).sum();
    let r2: f64 = d.iter().map(|z| z.re * z.re).sum();
    FeedthroughSignature {
        rms_magnitude: (s2 / m as f64).sqrt(),
        real_fraction: if s2 > 0.0 { r2 / s2 } else { 0.0 },
        d,
        fit: TemplateFit::new(res, explained, 2 * m, 1),
    }
}

/// The signature of a stiffness (suspension) in place of a free rigid body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StiffnessSignature {
    /// Fitted suspension frequency, Hz. Identified only when the band reaches down to
    /// about `2 f_hz`; below that the residual is `~ (w0 / w)^2 P` and only
    /// `gain * f_hz^2` is determined (see `equivalent_f_hz`).
    #[serde(with = "crate::serde_f64")]
    pub f_hz: f64,
    /// Fitted suspension damping.
    #[serde(with = "crate::serde_f64")]
    pub zeta: f64,
    /// Fitted gain per entry (`vec` order): the share of the entry's response that is
    /// the suspended body (1 where the rigid body dominates the low frequencies).
    pub gains: Vec<f64>,
    /// `f_hz * sqrt(g)`, `g` the weighted mean gain: the suspension frequency if the
    /// rigid body carried the whole low-frequency response (robust when `f_hz` is below
    /// the band).
    #[serde(with = "crate::serde_f64")]
    pub equivalent_f_hz: f64,
    /// The fit (`ny nu + 2` parameters).
    pub fit: TemplateFit,
}

/// Tests the residual for a stiffness replacing a free rigid body. Replacing `R / s^2`
/// by `R / (s^2 + 2 zeta w0 s + w0^2)` changes the response by
/// `P_rb q(s)`, `q = -(2 zeta w0 s + w0^2) / (s^2 + 2 zeta w0 s + w0^2)`
/// (`~ (w0 / w)^2` above `w0`, `-1` below): a low-frequency, in-phase relative
/// residual. The template is `E_ke ~ g_e q(j w_k) P_ke` with a real gain `g_e` per entry
/// (the rigid body's share of the entry's low-frequency response), and `w0`, `zeta`
/// common: `w0` on a logarithmic grid (8 per decade, from a tenth of the lowest line to
/// a tenth of the highest but at most 100 times the lowest: a stiffness sits at the
/// bottom of the band) at `zeta = 0.05`, then golden-section refinement of `f0` and of
/// `zeta` in `[1e-3, 1]`. Lines above `100 w0` (where `|q| < 1e-4`) are skipped.
pub fn stiffness_signature(res: &Residual) -> StiffnessSignature {
    let (n, m) = (res.n_lines(), res.ny * res.nu);
    // x = conj(P) E / var (real and imaginary parts apart, so that the inner loop
    // vectorises), y = |P|^2 / var.
    let mut xr = vec![0.0; n * m];
    let mut xi = vec![0.0; n * m];
    let mut y = vec![0.0; n * m];
    for i in 0..n * m {
        let p = res.model[i];
        let x = p.conj() * res.error[i] * res.weight[i];
        xr[i] = x.re;
        xi[i] = x.im;
        y[i] = p.norm_sqr() * res.weight[i];
    }
    let omega = &res.omega;
    // the entries are independent: chunks of them run in parallel, each summing over
    // the lines in order (the same sums as one serial pass)
    const CHUNK: usize = 256;
    let eval = |f0: f64, zeta: f64, gains: Option<(&mut Vec<f64>, &mut Vec<f64>)>| -> f64 {
        let w0 = TAU * f0;
        let kmax = omega.partition_point(|w| *w < 100.0 * w0);
        let q: Vec<C64> = omega[..kmax]
            .iter()
            .map(|&w| {
                let s = C64::new(0.0, w);
                let a = C64::new(w0 * w0, 0.0) + s * (2.0 * zeta * w0);
                -a / (s * s + a)
            })
            .collect();
        let parts: Vec<(Vec<f64>, Vec<f64>)> = (0..m.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let (e0, e1) = (c * CHUNK, ((c + 1) * CHUNK).min(m));
                let mut num = vec![0.0; e1 - e0];
                let mut den = vec![0.0; e1 - e0];
                for (k, q) in q.iter().enumerate() {
                    let q2 = q.norm_sqr();
                    let (lo, hi) = (k * m + e0, k * m + e1);
                    let (xrs, xis, ys) = (&xr[lo..hi], &xi[lo..hi], &y[lo..hi]);
                    for (((nu_e, de), (r, i)), yy) in num
                        .iter_mut()
                        .zip(den.iter_mut())
                        .zip(xrs.iter().zip(xis))
                        .zip(ys)
                    {
                        // Re(conj(q) x) = q.re x.re + q.im x.im
                        *nu_e += q.re * r + q.im * i;
                        *de += q2 * yy;
                    }
                }
                (num, den)
            })
            .collect();
        let num: Vec<f64> = parts.iter().flat_map(|(n, _)| n.iter().copied()).collect();
        let den: Vec<f64> = parts.iter().flat_map(|(_, d)| d.iter().copied()).collect();
        let mut total = 0.0;
        for e in 0..m {
            if den[e] > 0.0 {
                total += num[e] * num[e] / den[e];
            }
        }
        if let Some((g, d)) = gains {
            g.clear();
            g.extend((0..m).map(|e| if den[e] > 0.0 { num[e] / den[e] } else { 0.0 }));
            *d = den;
        }
        total
    };
    let fpos: Vec<f64> = res.freq_hz.iter().copied().filter(|f| *f > 0.0).collect();
    let (flo, fhi) = match (fpos.first(), fpos.last()) {
        (Some(a), Some(b)) => (a / 10.0, (b / 10.0).min(100.0 * a).max(a / 5.0)),
        _ => {
            return StiffnessSignature {
                f_hz: f64::NAN,
                zeta: f64::NAN,
                gains: vec![0.0; m],
                equivalent_f_hz: f64::NAN,
                fit: TemplateFit::new(res, 0.0, m + 2, 1),
            }
        }
    };
    let step = 10f64.powf(1.0 / 8.0);
    let mut best = (f64::NEG_INFINITY, flo);
    let mut f0 = flo;
    while f0 <= fhi * 1.000_001 {
        let v = eval(f0, 0.05, None);
        if v > best.0 {
            best = (v, f0);
        }
        f0 *= step;
    }
    let mut zeta = 0.05;
    let lf = golden_max(
        |lf| eval(10f64.powf(lf), zeta, None),
        (best.1 / step).log10(),
        (best.1 * step).log10(),
        16,
    );
    let f_hz = 10f64.powf(lf);
    let lz = golden_max(|lz| eval(f_hz, 10f64.powf(lz), None), -3.0, 0.0, 14);
    let cand = 10f64.powf(lz);
    if eval(f_hz, cand, None) > eval(f_hz, zeta, None) {
        zeta = cand;
    }
    let (mut gains, mut den) = (Vec::with_capacity(m), Vec::new());
    let explained = eval(f_hz, zeta, Some((&mut gains, &mut den)));
    let (mut gw, mut sw) = (0.0, 0.0);
    for e in 0..m {
        gw += gains[e] * den[e];
        sw += den[e];
    }
    let gbar = if sw > 0.0 { gw / sw } else { 0.0 };
    StiffnessSignature {
        f_hz,
        zeta,
        equivalent_f_hz: if gbar > 0.0 {
            f_hz * gbar.sqrt()
        } else {
            f64::NAN
        },
        gains,
        fit: TemplateFit::new(res, explained, m + 2, 1),
    }
}

/// The signature of a missed mode at `f_hz`: the template
/// `E_ke ~ u_e w^2 / (w^2 - w_k^2 + 2 j zeta w w_k)` (`w = 2 pi f_hz`) with a complex
/// residue `u_e` per entry, fitted by weighted least squares. (A lightly damped mode's
/// residue `c b^T` is real, but a delay or hold that the model applies to its whole
/// response rotates the missing mode's residual too: by 28 degrees at 520 Hz with the
/// 150 us of the reference wafer stage, enough to bias a real-residue fit's damping by
/// 20 %.) `zeta` is the picker's half-power estimate refined by a golden-section search
/// on `log zeta` within half a decade of it (or searched up to 0.3 when the picker left
/// it unresolved), never below `df / f_hz` (a half-power bandwidth of two line spacings:
/// a narrower "mode" would fit a single noisy line). The fit runs over the lines within
/// `+-max(20 %, 5 half-power bandwidths)` of `f_hz` (at least 50 lines each side), where
/// the template holds nearly all its energy; `explained_fraction` is relative to the
/// whole residual's excess. Returns `(zeta, fit)` with `2 ny nu + 2` parameters.
pub fn mode_signature(res: &Residual, f_hz: f64, zeta_hint: Option<f64>) -> (f64, TemplateFit) {
    let (n, m) = (res.n_lines(), res.ny * res.nu);
    let f = &res.freq_hz;
    if !(f_hz.is_finite() && f_hz > 0.0) || n == 0 {
        return (f64::NAN, TemplateFit::new(res, 0.0, 2 * m + 2, 1));
    }
    let wp = TAU * f_hz;
    let mut num = vec![C64::new(0.0, 0.0); m];
    let mut den = vec![0.0; m];
    let k0 = f.partition_point(|x| *x < f_hz);
    let mut eval = |zeta: f64| -> f64 {
        let half = (0.2f64).max(5.0 * zeta);
        let a = f
            .partition_point(|x| *x < f_hz * (1.0 - half))
            .min(k0.saturating_sub(50));
        let b = f
            .partition_point(|x| *x <= f_hz * (1.0 + half))
            .max((k0 + 50).min(n));
        num.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
        den.iter_mut().for_each(|v| *v = 0.0);
        for k in a..b {
            let w = res.omega[k];
            let h = C64::new(wp * wp, 0.0) / C64::new(wp * wp - w * w, 2.0 * zeta * wp * w);
            let (hc, h2) = (h.conj(), h.norm_sqr());
            for e in 0..m {
                let i = k * m + e;
                num[e] += hc * res.error[i] * res.weight[i];
                den[e] += h2 * res.weight[i];
            }
        }
        (0..m)
            .filter(|e| den[*e] > 0.0)
            .map(|e| num[e].norm_sqr() / den[e])
            .sum()
    };
    // A resolved mode spans at least a few lines: half-power bandwidth 2 zeta f of at
    // least two line spacings (otherwise a single noisy line passes for a mode).
    let df = if k0 > 0 && k0 < n {
        f[k0] - f[k0 - 1]
    } else if n > 1 {
        f[1] - f[0]
    } else {
        0.0
    };
    let zmin = (df / f_hz).clamp(1e-4, 0.1).log10();
    let (lo, hi) = match zeta_hint {
        Some(z) if z.is_finite() && z > 0.0 => {
            let lz = z.clamp(1e-4, 0.3).log10();
            ((lz - 0.5).max(zmin), (lz + 0.5).min(-0.5).max(zmin + 0.1))
        }
        _ => (zmin, -0.5),
    };
    let lz = golden_max(|lz| eval(10f64.powf(lz)), lo, hi, 30);
    let zeta = 10f64.powf(lz);
    let explained = eval(zeta);
    (zeta, TemplateFit::new(res, explained, 2 * m + 2, 1))
}

/// Golden-section search for the maximum of `f` on `[a, b]`.
fn golden_max(mut f: impl FnMut(f64) -> f64, mut a: f64, mut b: f64, iters: usize) -> f64 {
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = b - r * (b - a);
    let mut d = a + r * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..iters {
        if fc >= fd {
            b = d;
            d = c;
            fd = fc;
            c = b - r * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + r * (b - a);
            fd = f(d);
        }
    }
    if fc >= fd {
        c
    } else {
        d
    }
}

/// The second-order template of a dynamics factor: `w0^2 / (s^2 + 2 zeta w0 s + w0^2)`
/// (a mount resonance, or a second-order low-pass), fitted to one support.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SecondOrderFactor {
    /// Natural frequency `w0 / 2 pi`, Hz.
    #[serde(with = "crate::serde_f64")]
    pub f_hz: f64,
    /// Relative damping `zeta`.
    #[serde(with = "crate::serde_f64")]
    pub zeta: f64,
    /// The fit (2 parameters; p-value Bonferroni-corrected like the first-order one).
    pub fit: TemplateFit,
}

/// The signature of a dynamics factor of unit static gain common to one input column
/// (actuator dynamics), one output row (sensor dynamics) or every entry (an amplifier
/// or sensor bandwidth shared by all channels): the first-order template and the
/// second-order one, each fitted to the residual of that support.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IoFactor {
    /// The column (input) or row (output), 0-based; 0 for the common factor.
    pub index: usize,
    /// Its share of the residual's excess energy (from [`crate::Concentration`]; 1 for
    /// the common factor).
    pub energy_fraction: f64,
    /// Time constant `tau` of the factor `1 / (1 + j w tau)`, seconds; negative for a
    /// lead (or when the model has too much lag).
    pub tau_s: f64,
    /// Standard error of `tau_s`.
    #[serde(with = "crate::serde_f64")]
    pub tau_std_s: f64,
    /// `1 / (2 pi |tau|)`, Hz.
    #[serde(with = "crate::serde_f64")]
    pub pole_hz: f64,
    /// The first-order fit (1 parameter; p-value Bonferroni-corrected over the rows or
    /// columns). For a row or column, flagged only for the dominant row or column of
    /// [`crate::Concentration`].
    pub fit: TemplateFit,
    /// The second-order template `w0^2 / (s^2 + 2 zeta w0 s + w0^2)` on the same
    /// support (flagged under the same conditions as `fit`).
    pub second_order: SecondOrderFactor,
}

impl IoFactor {
    /// The order the residual supports, 1 or 2: 2 for a resonance, when the
    /// second-order template is underdamped (`zeta <= 0.5`: complex poles; an overdamped
    /// one is a first-order lag with a far pole added), has its natural frequency inside
    /// `[f_lo / 2, 2 f_hi]` (beyond it, the template only bends the first-order one's
    /// phase slope) and explains significantly more than the first-order one: its extra
    /// parameter's explained energy over the calibrated scale `c` (the per-line scale of
    /// [`crate::Residual::line_null`]) beyond the `chi2(1)` quantile at `alpha`, and at
    /// least 5 % more of the excess (a first fit that absorbed part of a lag leaves a
    /// residual that no template fits exactly, and a second parameter always takes some
    /// of it).
    pub fn order(&self, c: f64, alpha: f64, band_hz: (f64, f64)) -> usize {
        let so = &self.second_order;
        let gain = (so.fit.explained - self.fit.explained) / c.max(f64::MIN_POSITIVE);
        let inside = so.f_hz >= 0.5 * band_hz.0 && so.f_hz <= 2.0 * band_hz.1;
        let resonant = so.zeta <= 0.5;
        let more = so.fit.explained_fraction - self.fit.explained_fraction >= 0.05;
        if inside && resonant && more && gain > crate::stats::chi2_isf(alpha, 1.0) {
            2
        } else {
            1
        }
    }
}

/// Explained energy `sum_k 2 Re(conj(g_k) B_k) - |g_k|^2 A_k` of the second-order
/// template `g_k = w0^2 / (w0^2 - w_k^2 + 2 j zeta w0 w_k) - 1` (see
/// [`second_order_terms`]), with `w_sq[k] = w_k^2`.
fn explained_second_order(
    omega: &[f64],
    w_sq: &[f64],
    a: &[f64],
    b: &[C64],
    f0: f64,
    zeta: f64,
) -> f64 {
    let w0 = TAU * f0;
    let (w0_sq, two_zw0) = (w0 * w0, 2.0 * zeta * w0);
    let mut sum = 0.0;
    for k in 0..omega.len() {
        let (gr, gi, g2) = second_order_terms(omega[k], w_sq[k], w0_sq, two_zw0);
        sum += 2.0 * (gr * b[k].re + gi * b[k].im) - g2 * a[k];
    }
    sum
}

/// The grid of the second-order template's `(log10 f0, log10 zeta)`: 48 natural
/// frequencies per decade from a fifth of the lowest line to five times the highest,
/// and 10 dampings from 0.005 to 1, frequency-major. `None` without a positive line.
struct SecondOrderGrid {
    /// `log10 f0` of the frequency points.
    lf: Vec<f64>,
    /// Their spacing.
    step_f: f64,
}

impl SecondOrderGrid {
    const ZETAS: [f64; 10] = [0.005, 0.01, 0.02, 0.035, 0.06, 0.1, 0.2, 0.35, 0.6, 1.0];

    fn new(omega: &[f64]) -> Option<Self> {
        let w_lo = *omega.iter().find(|w| **w > 0.0)?;
        let w_hi = *omega.iter().rev().find(|w| **w > 0.0)?;
        let (lf_lo, lf_hi) = ((0.2 * w_lo / TAU).log10(), (5.0 * w_hi / TAU).log10());
        let n_f = (((lf_hi - lf_lo) * 48.0).ceil() as usize).clamp(8, 400);
        let lf = (0..n_f)
            .map(|i| lf_lo + (lf_hi - lf_lo) * i as f64 / (n_f - 1) as f64)
            .collect();
        Some(Self {
            lf,
            step_f: (lf_hi - lf_lo) / (n_f - 1) as f64,
        })
    }

    /// The `(log10 f0, log10 zeta)` of grid point `g`.
    fn point(&self, g: usize) -> (f64, f64) {
        let nz = Self::ZETAS.len();
        (self.lf[g / nz], Self::ZETAS[g % nz].log10())
    }

    fn len(&self) -> usize {
        self.lf.len() * Self::ZETAS.len()
    }
}

/// The best grid point of the second-order template for every support at once:
/// `(log10 f0, log10 zeta, explained)` for each `(A, B)` of `sums`.
///
/// The explained energy is linear in the per-line sums: at grid point `g` it is
/// `sum_k 2 (Re g_k Re B_k + Im g_k Im B_k) - |g_k|^2 A_k`, a row of `T` (the template
/// `[2 Re g, 2 Im g, -|g|^2]` over the lines) times a column of `S` (`[Re B; Im B; A]`
/// of one support). Every support's grid is therefore one matrix product `T S`, in
/// blocks of grid points: the template is evaluated once per line and grid point, not
/// once per support (at 50 x 50 entries, 100 supports share it).
fn best_grid_points(
    omega: &[f64],
    grid: &SecondOrderGrid,
    sums: &[(Vec<f64>, Vec<C64>)],
) -> Vec<(f64, f64, f64)> {
    let (n, ns) = (omega.len(), sums.len());
    let mut best = vec![(0.0, 0.0, f64::NEG_INFINITY); ns];
    if ns == 0 || n == 0 {
        return best;
    }
    let s = faer::Mat::<f64>::from_fn(3 * n, ns, |r, c| {
        let (a, b) = &sums[c];
        match r / n {
            0 => b[r % n].re,
            1 => b[r % n].im,
            _ => a[r % n],
        }
    });
    const BLOCK: usize = 64;
    let mut t = faer::Mat::<f64>::zeros(BLOCK, 3 * n);
    let mut g0 = 0;
    while g0 < grid.len() {
        let nb = BLOCK.min(grid.len() - g0);
        for r in 0..nb {
            let (lf, lz) = grid.point(g0 + r);
            let w0 = TAU * 10f64.powf(lf);
            let (w0_sq, two_zw0) = (w0 * w0, 2.0 * 10f64.powf(lz) * w0);
            for (k, &w) in omega.iter().enumerate() {
                let (gr, gi, g2) = second_order_terms(w, w * w, w0_sq, two_zw0);
                t[(r, k)] = 2.0 * gr;
                t[(r, n + k)] = 2.0 * gi;
                t[(r, 2 * n + k)] = -g2;
            }
        }
        let e = t.as_ref().subrows(0, nb) * &s;
        for (c, bc) in best.iter_mut().enumerate() {
            for r in 0..nb {
                let v = e[(r, c)];
                if v > bc.2 {
                    let (lf, lz) = grid.point(g0 + r);
                    *bc = (lf, lz, v);
                }
            }
        }
        g0 += nb;
    }
    best
}

/// `(Re g, Im g, |g|^2)` of the second-order template
/// `g = w0^2 / (w0^2 - w^2 + 2 j zeta w0 w) - 1` at `w` (`w_sq = w^2`,
/// `two_zw0 = 2 zeta w0`): with `d_r = w0^2 - w^2` and `d_i = 2 zeta w0 w`,
/// `g = ((w^2 d_r - d_i^2) - j d_i w0^2) / (d_r^2 + d_i^2)` and
/// `|g|^2 = (w^4 + d_i^2) / (d_r^2 + d_i^2)`: one real division.
#[inline]
fn second_order_terms(w: f64, w_sq: f64, w0_sq: f64, two_zw0: f64) -> (f64, f64, f64) {
    let dr = w0_sq - w_sq;
    let di = two_zw0 * w;
    let inv = 1.0 / (dr * dr + di * di);
    (
        (w_sq * dr - di * di) * inv,
        -di * w0_sq * inv,
        (w_sq * w_sq + di * di) * inv,
    )
}

/// Fits the second-order template to the per-line sums `(a, b)` from the best point of
/// its [`SecondOrderGrid`] (`start`, from [`best_grid_points`]): alternating
/// golden-section refinements of `log f0` and `log zeta` around it. Returns
/// `(f0, zeta, explained)`.
fn refine_second_order(
    omega: &[f64],
    a: &[f64],
    b: &[C64],
    grid: &SecondOrderGrid,
    (mut best_lf, mut best_lz, best): (f64, f64, f64),
) -> (f64, f64, f64) {
    let w_sq: Vec<f64> = omega.iter().map(|w| w * w).collect();
    let ev = |lf: f64, lz: f64| {
        let (f0, z) = (10f64.powf(lf), 10f64.powf(lz));
        explained_second_order(omega, &w_sq, a, b, f0, z)
    };
    let (mut hf, mut hz) = (grid.step_f, 0.25);
    for _ in 0..4 {
        best_lf = golden_max(|lf| ev(lf, best_lz), best_lf - hf, best_lf + hf, 25);
        best_lz = golden_max(
            |lz| ev(best_lf, lz),
            (best_lz - hz).max(-3.0),
            (best_lz + hz).min(0.3),
            25,
        );
        hf *= 0.5;
        hz *= 0.5;
    }
    let v = ev(best_lf, best_lz);
    if v >= best {
        (10f64.powf(best_lf), 10f64.powf(best_lz), v)
    } else {
        // the grid point stays the estimate when the refinement found nothing better
        (10f64.powf(best_lf), 10f64.powf(best_lz), best)
    }
}

/// The first- and second-order templates of a factor with the per-line sums `(a, b)`
/// of its support (see [`IoFactor`]) and the best point of the second-order grid
/// (`start`), with the p-values corrected for `n_cand` supports.
fn factor_on(
    res: &Residual,
    (a, b): &(Vec<f64>, Vec<C64>),
    grid: Option<&SecondOrderGrid>,
    start: (f64, f64, f64),
    n_cand: usize,
) -> (FactorFit, SecondOrderFactor) {
    let (c, _) = res.line_null();
    let f = fit_factor(&res.omega, a, b, Factor::FirstOrder, c);
    let (f0, zeta, explained) = match grid {
        Some(grid) => refine_second_order(&res.omega, a, b, grid, start),
        None => (f64::NAN, f64::NAN, 0.0),
    };
    let second = SecondOrderFactor {
        f_hz: f0,
        zeta,
        fit: TemplateFit::new(res, explained, 2, n_cand),
    };
    (f, second)
}

/// The per-line sums of [`line_sums`] of every input column (`0..nu`) and every output
/// row (`nu..nu + ny`), in one pass over the residual (lines in parallel).
fn column_and_row_sums(res: &Residual) -> Vec<(Vec<f64>, Vec<C64>)> {
    let (n, ny, nu) = (res.n_lines(), res.ny, res.nu);
    let m = ny * nu;
    let per_line: Vec<(Vec<f64>, Vec<C64>)> = (0..n)
        .into_par_iter()
        .map(|k| {
            let mut a = vec![0.0; nu + ny];
            let mut b = vec![C64::new(0.0, 0.0); nu + ny];
            for j in 0..nu {
                for i in 0..ny {
                    let idx = k * m + j * ny + i;
                    let p = res.model[idx];
                    let w = res.weight[idx];
                    let (pa, pb) = (w * p.norm_sqr(), p.conj() * res.error[idx] * w);
                    a[j] += pa;
                    b[j] += pb;
                    a[nu + i] += pa;
                    b[nu + i] += pb;
                }
            }
            (a, b)
        })
        .collect();
    (0..nu + ny)
        .map(|s| {
            (
                per_line.iter().map(|(a, _)| a[s]).collect(),
                per_line.iter().map(|(_, b)| b[s]).collect(),
            )
        })
        .collect()
}

fn io_factor(
    res: &Residual,
    index: usize,
    energy_fraction: f64,
    (f, second): (FactorFit, SecondOrderFactor),
    n_cand: usize,
    flaggable: bool,
) -> IoFactor {
    let mut fit = TemplateFit::new(res, f.explained, 1, n_cand);
    fit.significant &= flaggable;
    let mut second = second;
    second.fit.significant &= flaggable;
    IoFactor {
        index,
        energy_fraction,
        tau_s: f.theta,
        tau_std_s: f.std,
        pole_hz: if f.theta != 0.0 {
            1.0 / (TAU * f.theta.abs())
        } else {
            f64::INFINITY
        },
        fit,
        second_order: second,
    }
}

/// Tests every input column and every output row for a factor the model lacks: for
/// column `j`, `E_:j = P_:j (h(j w) - 1)` (an actuator's bandwidth or mount resonance),
/// for row `i` the same with `P_i:` (a sensor's), with `h` the first-order lag
/// `1 / (1 + j w tau)` and, separately, the second-order `w0^2 / (s^2 + 2 zeta w0 s +
/// w0^2)`. `tau` is fitted by Gauss-Newton on the exact factor from the small-`tau`
/// estimate (a factor `~ 1 - j w tau` at low frequency, a delay on that column alone);
/// `w0` and `zeta` by a grid and golden-section refinement. A factor common to all
/// columns (a delay) explains about `1 / nu` of the excess in each column, so a column
/// is flagged only when it is the dominant column of `conc` and its factor explains
/// `min_explained` of the **total** excess. Returns (columns, rows).
///
/// A second-order factor on one row differs from a missed mode in the residual's
/// structure: it multiplies the whole row (every mode and the rigid body, seen through a
/// resonance) and leaves the other rows untouched, while a mode adds a rank-one term to
/// every entry with its mode shape; the concentration in that row proposes the support.
pub fn io_factors(
    res: &Residual,
    conc: &crate::residual::Concentration,
) -> (Vec<IoFactor>, Vec<IoFactor>) {
    let (ny, nu) = (res.ny, res.nu);
    // the per-line sums of every column and row, and their second-order grids in one
    // matrix product; then every column and row is refined and fitted on its own, in
    // parallel, in order
    let sums = column_and_row_sums(res);
    let grid = SecondOrderGrid::new(&res.omega);
    let starts = match &grid {
        Some(g) => best_grid_points(&res.omega, g, &sums),
        None => vec![(0.0, 0.0, f64::NEG_INFINITY); sums.len()],
    };
    let fit = |s: usize, n_cand: usize| factor_on(res, &sums[s], grid.as_ref(), starts[s], n_cand);
    let cols = (0..nu)
        .into_par_iter()
        .map(|j| {
            io_factor(
                res,
                j,
                conc.col_fraction[j],
                fit(j, nu),
                nu,
                conc.dominant_col == Some(j),
            )
        })
        .collect();
    let rows = (0..ny)
        .into_par_iter()
        .map(|i| {
            io_factor(
                res,
                i,
                conc.row_fraction[i],
                fit(nu + i, ny),
                ny,
                conc.dominant_row == Some(i),
            )
        })
        .collect();
    (cols, rows)
}

/// Tests the residual for a factor common to every entry (the bandwidth of an amplifier
/// that drives all actuators, or of the sensor electronics): `E = P (h(j w) - 1)` over
/// all entries, with the first- and second-order templates of [`io_factors`]. Unlike a
/// delay (`e^{-j w d}`, unit magnitude), a lag also lowers the magnitude,
/// `|h|^2 = 1 / (1 + (w tau)^2)`. Flagged as described in the module documentation.
pub fn common_factor(res: &Residual) -> IoFactor {
    let sums = line_sums(res, |_| true);
    let grid = SecondOrderGrid::new(&res.omega);
    let start = grid.as_ref().map_or((0.0, 0.0, f64::NEG_INFINITY), |g| {
        best_grid_points(&res.omega, g, std::slice::from_ref(&sums))[0]
    });
    let fits = factor_on(res, &sums, grid.as_ref(), start, 1);
    io_factor(res, 0, 1.0, fits, 1, true)
}

/// A peak of the CMIF of the noise-whitened residual: where the model may miss a mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualPeak {
    /// Peak frequency, Hz (the CMIF picker's enhanced-FRF maximum, parabola-refined).
    pub f_hz: f64,
    /// The line of the peak.
    pub line: usize,
    /// Singular value index, 0-based (0 = the largest).
    pub sv_index: usize,
    /// `sigma_i^2` of the residual at the peak over the calibrated noise energy of the
    /// whole line (`kappa sum_e var_e`): a power ratio, above 1 when this one singular
    /// direction holds more than all the noise of the line (pure noise gives about
    /// 0.3-0.6 for `sigma_1` of a 4 x 13 matrix).
    #[serde(with = "crate::serde_f64")]
    pub height_over_noise: f64,
    /// The picker's prominence, dB (`None` for a localized excess the picker did not
    /// return as a peak).
    pub prominence_db: Option<f64>,
    /// Half-power damping estimate of the picker, when resolved.
    pub damping: Option<f64>,
    /// The line statistic at the peak over the calibrated noise mean (`s_k / (c nu)`).
    #[serde(with = "crate::serde_f64")]
    pub line_ratio: f64,
    /// Share of the residual's excess energy in the localized region around the peak.
    pub excess_fraction: f64,
    /// Damping of the fitted mode template ([`mode_signature`]); NaN when the template
    /// was not fitted.
    #[serde(with = "crate::serde_f64")]
    pub fit_zeta: f64,
    /// The fit of a mode at `f_hz` (complex residue per entry) to the residual
    /// ([`mode_signature`]), evaluated only when the peak passes the other conditions of
    /// `significant` (explained 0 otherwise).
    pub fit: TemplateFit,
    /// The two-sided rise of the relative residual at the peak
    /// ([`crate::Residual::relative_rise`]): >> 1 for a resonance that the model does
    /// not share, ~1 for the model's own resonance seen through a smooth factor.
    #[serde(with = "crate::serde_f64")]
    pub relative_rise: f64,
    /// The residual is significant, the peak lies in a region of the localized test of
    /// [`crate::residual`], its `relative_rise` reaches
    /// [`crate::ResidualConfig::peak_over_local`], its height over the noise exceeds
    /// [`crate::ResidualConfig::min_peak_height`] and the mode template's p-value is
    /// below `alpha`: a missed-mode candidate. (No minimum explained fraction: with
    /// several missed modes each explains only its share.)
    pub significant: bool,
    /// False for a localized excess that the CMIF picker did not return as a peak
    /// (reported at its highest line).
    pub from_picker: bool,
}

/// The peaks of the CMIF (`frf_data::cmif`) of the residual `E` where the residual has
/// localized excess (the regions of the localized test of [`crate::residual`]), highest
/// first, at most [`crate::ResidualConfig::max_peaks`].
///
/// A missed mode `c b^T / (s^2 + 2 zeta w s + w^2)` is rank one: it raises one singular
/// value of `E` at its damped natural frequency, with singular vectors along its mode
/// shapes. The CMIF is taken of `E` itself (not of the noise-whitened residual, whose
/// peak the frequency dependence of the noise variance would shift: by 1-2 % on the
/// reference data) with the calibrated noise variance (`kappa var`), so that the
/// picker measures prominences against the noise; each localized region is analysed
/// with `+-max(local_rel, 6 %)` of frequency around it (the picker's windows need
/// +-5 %). The height over the noise is in noise units and does not depend on that
/// choice. The picker runs only on regions that hold a peak of the relative residual
/// ([`crate::Residual::relative_rise`]): elsewhere the localized excess is a resonance of
/// the model seen through a smooth factor the model lacks, and no missed mode; such
/// regions, and regions the picker returns no peak for, are reported at their highest
/// line (`from_picker = false`). This also keeps the cost small (the picker on the
/// whole band of pure noise examines thousands of candidates; a delay's residual has a
/// region at every resonance).
///
/// Errors: the CMIF fails (a non-converging SVD).
pub fn residual_peaks(res: &Residual) -> Result<Vec<ResidualPeak>, ValidationError> {
    let (n, ny, nu) = (res.n_lines(), res.ny, res.nu);
    let m = ny * nu;
    let regions = localized_regions(res);
    if regions.is_empty() {
        return Ok(Vec::new());
    }
    let kappa = res.entry_noise_energy().max(f64::MIN_POSITIVE);
    let mu = res.null.mean().max(f64::MIN_POSITIVE);
    let sig = res.significance().significant;
    let f = &res.freq_hz;
    let ext = res.cfg.local_rel.max(0.06);
    let h = res.cfg.local_half_window;
    // Analysis windows around the regions that hold a peak of the relative residual
    // (only those can hold a missed mode), merged.
    let mut windows: Vec<std::ops::Range<usize>> = Vec::new();
    for rg in regions
        .iter()
        .filter(|rg| is_relative_peak(res, (*rg).clone()))
    {
        let a = f
            .partition_point(|x| *x < f[rg.start] * (1.0 - ext))
            .min(rg.start.saturating_sub(h));
        let b = f
            .partition_point(|x| *x <= f[rg.end - 1] * (1.0 + ext))
            .max((rg.end + h).min(n));
        match windows.last_mut() {
            Some(w) if a <= w.end => w.end = w.end.max(b),
            _ => windows.push(a..b),
        }
    }
    let in_region = |k: usize| {
        regions
            .iter()
            .find(|rg| rg.start <= k + 2 && k < rg.end + 2)
    };
    let line_noise = |k: usize| -> f64 {
        kappa
            * res.weight[k * m..(k + 1) * m]
                .iter()
                .map(|w| 1.0 / w)
                .sum::<f64>()
    };
    let thr = res.cfg.peak_over_local;
    // The mode template is fitted only to candidates (the cheap tests first): the
    // residual of a smooth factor has a peak at every resonance of the model.
    let mode_fit_if = |candidate: bool, f_hz: f64, zeta: Option<f64>| -> (f64, TemplateFit) {
        if candidate {
            mode_signature(res, f_hz, zeta)
        } else {
            (f64::NAN, TemplateFit::new(res, 0.0, 2 * m + 2, 1))
        }
    };
    let mut out: Vec<ResidualPeak> = Vec::new();
    for w in &windows {
        let frf = Frf::new(
            f[w.clone()].to_vec(),
            ny,
            nu,
            res.error[w.start * m..w.end * m].to_vec(),
            Some(
                res.weight[w.start * m..w.end * m]
                    .iter()
                    .map(|x| kappa / x)
                    .collect(),
            ),
        )?;
        let cm = cmif(&frf)?;
        for p in pick_peaks(&cm, &res.cfg.peak) {
            if p.line >= cm.n_lines() || p.sv_index >= cm.n_sv() {
                continue;
            }
            let k = w.start + p.line;
            let Some(rg) = in_region(k) else { continue };
            let relative_rise = res.relative_rise(k);
            let height_over_noise = cm.sv2[p.line][p.sv_index] / line_noise(k);
            let candidate =
                sig && relative_rise >= thr && height_over_noise > res.cfg.min_peak_height;
            let (fit_zeta, fit) = mode_fit_if(candidate, p.f_hz, p.damping);
            let significant = candidate && fit.p_value < res.cfg.alpha;
            out.push(ResidualPeak {
                f_hz: p.f_hz,
                line: k,
                sv_index: p.sv_index,
                height_over_noise,
                prominence_db: Some(p.prominence),
                damping: p.damping,
                line_ratio: res.line_stat[k] / mu,
                excess_fraction: region_excess_fraction(res, rg.clone()),
                fit_zeta,
                fit,
                relative_rise,
                significant,
                from_picker: true,
            });
        }
    }
    // Localized regions without a picked peak.
    for rg in &regions {
        if out
            .iter()
            .any(|p| rg.start <= p.line + 2 && p.line < rg.end + 2)
        {
            continue;
        }
        let k = (rg.start..rg.end)
            .max_by(|a, b| res.line_stat[*a].total_cmp(&res.line_stat[*b]))
            .unwrap_or(rg.start);
        let sv1 = {
            let g = faer::MatRef::from_column_major_slice(&res.error[k * m..(k + 1) * m], ny, nu);
            g.singular_values()
                .ok()
                .and_then(|v| v.first().copied())
                .unwrap_or(0.0)
        };
        let relative_rise = res.relative_rise(k);
        let height_over_noise = sv1 * sv1 / line_noise(k);
        let candidate = sig && relative_rise >= thr && height_over_noise > res.cfg.min_peak_height;
        let (fit_zeta, fit) = mode_fit_if(candidate, f[k], None);
        let significant = candidate && fit.p_value < res.cfg.alpha;
        out.push(ResidualPeak {
            f_hz: f[k],
            line: k,
            sv_index: 0,
            height_over_noise,
            prominence_db: None,
            damping: None,
            line_ratio: res.line_stat[k] / mu,
            excess_fraction: region_excess_fraction(res, rg.clone()),
            fit_zeta,
            fit,
            relative_rise,
            significant,
            from_picker: false,
        });
    }
    out.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(b.height_over_noise.total_cmp(&a.height_over_noise))
    });
    out.truncate(res.cfg.max_peaks);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The one-division form of [`explained_second_order`] against the template
    /// evaluated in complex arithmetic, over frequencies through and far from the
    /// resonance and dampings from 0.005 to 1.
    #[test]
    fn second_order_explained_energy_matches_the_complex_template() {
        let omega: Vec<f64> = (0..400).map(|k| TAU * (5.0 + 7.3 * k as f64)).collect();
        let w_sq: Vec<f64> = omega.iter().map(|w| w * w).collect();
        let a: Vec<f64> = (0..400)
            .map(|k| 1.0 + (k as f64 * 0.37).sin().abs())
            .collect();
        let b: Vec<C64> = (0..400)
            .map(|k| C64::new((k as f64 * 0.11).cos(), (k as f64 * 0.23).sin()))
            .collect();
        for f0 in [3.0, 120.0, 1234.5, 2920.0, 9000.0] {
            for zeta in [0.005, 0.03, 0.2, 1.0] {
                let w0 = TAU * f0;
                let direct: f64 = omega
                    .iter()
                    .zip(a.iter().zip(&b))
                    .map(|(&w, (&ak, bk))| {
                        let g = C64::new(w0 * w0, 0.0)
                            / C64::new(w0 * w0 - w * w, 2.0 * zeta * w0 * w)
                            - 1.0;
                        2.0 * (g.conj() * bk).re - g.norm_sqr() * ak
                    })
                    .sum();
                let fast = explained_second_order(&omega, &w_sq, &a, &b, f0, zeta);
                let scale: f64 = a.iter().sum::<f64>() + b.iter().map(|v| v.norm()).sum::<f64>();
                assert!(
                    (fast - direct).abs() <= 1e-12 * scale.max(direct.abs()),
                    "f0 {f0}, zeta {zeta}: {fast} against {direct}"
                );
            }
        }
    }

    /// The grid searched for all supports at once (one matrix product) finds, for each
    /// support, the grid point and value of a direct search with
    /// [`explained_second_order`]; a support built from one resonance template is found
    /// at its grid point.
    #[test]
    fn batched_grid_matches_the_direct_search() {
        let omega: Vec<f64> = (0..600).map(|k| TAU * (20.0 + 3.1 * k as f64)).collect();
        let w_sq: Vec<f64> = omega.iter().map(|w| w * w).collect();
        let grid = SecondOrderGrid::new(&omega).unwrap();
        // B_k = conj(g_k) A_k for a template at a grid point: explained = sum |g|^2 A, the
        // largest over the grid at that point
        let (lf_true, lz_true) = grid.point(7 * 10 + 3);
        let (f_true, z_true) = (10f64.powf(lf_true), 10f64.powf(lz_true));
        let a: Vec<f64> = (0..600)
            .map(|k| 1.0 + 0.5 * (k as f64 * 0.05).cos())
            .collect();
        let w0 = TAU * f_true;
        let b_true: Vec<C64> = omega
            .iter()
            .zip(&a)
            .map(|(&w, &ak)| {
                let (gr, gi, _) = second_order_terms(w, w * w, w0 * w0, 2.0 * z_true * w0);
                C64::new(gr, gi) * ak
            })
            .collect();
        let b_other: Vec<C64> = (0..600)
            .map(|k| C64::new((k as f64 * 0.013).sin(), (k as f64 * 0.029).cos()))
            .collect();
        let sums = vec![(a.clone(), b_true), (a.clone(), b_other)];
        let batched = best_grid_points(&omega, &grid, &sums);
        for (s, (aa, bb)) in sums.iter().enumerate() {
            let mut direct = (0.0, 0.0, f64::NEG_INFINITY);
            for g in 0..grid.len() {
                let (lf, lz) = grid.point(g);
                let v =
                    explained_second_order(&omega, &w_sq, aa, bb, 10f64.powf(lf), 10f64.powf(lz));
                if v > direct.2 {
                    direct = (lf, lz, v);
                }
            }
            let (lf, lz, v) = batched[s];
            assert_eq!((lf, lz), (direct.0, direct.1), "support {s}");
            assert!(
                (v - direct.2).abs() <= 1e-10 * direct.2.abs().max(1.0),
                "support {s}: {v} vs {}",
                direct.2
            );
        }
        assert_eq!((batched[0].0, batched[0].1), (lf_true, lz_true));
    }
}
