//! Delay estimation and compensation without a model: the *delay periodogram* of the
//! squared FRF, with a robust refinement.
//!
//! A sampled measurement of a continuous plant sees the plant through a zero-order hold
//! (a delay of half a sample, `e^{-j w Ts/2}` times a real, positive `sinc` droop) and a
//! computation delay (often one sample). Section 4.2 of the wafer-stage paper determines
//! these delays from the FRF and compensates the data before fitting in continuous time
//! (Wang and Garnier 2008, ch. 8). This module does that without a model.
//!
//! **Principle.** For a lightly damped structure with (nearly) real modes,
//! `P(j w) = R_rb / (j w)^2 + sum_i c_i b_i^T / (w_i^2 - w^2 + 2 j zeta_i w_i w)` is
//! (nearly) real away from the resonances (displacement per force; `j` times real for
//! velocity, real again for acceleration). The measured `G = P e^{-j w tau}` therefore
//! satisfies `G^2 e^{2 j w tau} ~ |G|^2 > 0` (or `< 0` for velocity): squaring removes
//! the sign flips of the real response at every resonance and anti-resonance, which
//! would otherwise make phase unwrapping fail. With the per-line, magnitude-weighted
//! average of the squared, unit-modulus entries,
//!
//! `s_k = sum_e G_ke^2 / |G_ke|  /  sum_e |G_ke|`  (`|s_k| <= 1`),
//!
//! the delay maximises the periodogram `|D(tau)|`, `D(tau) = Re sum_k s_k e^{2 j w_k tau}`
//! (all terms positive real at the true delay; the lines through resonances, where the
//! phase turns by 180 degrees, add incoherent terms that average out for lightly damped
//! systems). The search runs on a grid of `1 / (32 f_max)` over the configured range
//! (the main lobe of `D` is `1 / (4 f_max)` wide), then a golden-section search refines
//! the best grid point to [`DelayConfig::tolerance_s`].
//!
//! **Robust refinement.** Entries near their own resonances and anti-resonances have
//! phases far from the delay line and pull the plain maximum. Within one grid step of it,
//! the estimate is refined on `R(tau) = sum_k sum_e a_ke max(x_ke, 0)^p`, where
//! `x_ke = Re(+-q_ke e^{2 j w_k tau})` is the cosine of entry `e`'s doubled phase error,
//! `q_ke = G_ke^2 / |G_ke|^2` and `a_ke` its weight in `s_k`: a redescending M-estimate
//! in which an entry off by more than about `1 / sqrt(p)` rad stops counting
//! ([`DelayConfig::robust_power`], default 16; 0 keeps the plain maximum).
//!
//! **Bias.** The method assumes real modes and no damping phase. A damped mode adds a
//! phase lag of about `2 zeta w / w_r` below its resonance (a delay of `2 zeta / w_r`
//! weighted by its share of the response) and a lead of about `2 zeta w_r / w` above
//! it, so lightly damped data give a bias of a few microseconds: on simulated plants
//! with damping 0.002..0.03 and lines up to 2 kHz the errors are within 6 us (see the
//! tests), on the reference wafer stage 2.7 us. The uncertainty below measures the
//! scatter of the lines, not this bias.
//!
//! **Uncertainty.** For the plain periodogram, `tau` solves `D'(tau) = 0` with `D' = -2 sum_k w_k Im(s_k e^{2 j w_k
//! tau})` (for the positive branch); treating the lines as independent, the sandwich
//! (curvature) estimate is `std(tau) = sqrt(sum_k t_k^2) / |D''(tau)|` with
//! `t_k = 2 w_k Im(s_k e^{2 j w_k tau})` and `D'' = -4 sum_k w_k^2 Re(s_k e^{2 j w_k
//! tau})`; the robust refinement uses the same sandwich on `R` (with `R''` by central
//! differences). It measures how consistently the lines agree on the delay.

use crate::{Frf, FrfDataset, FrfError, C64};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Settings of [`estimate_delay`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DelayConfig {
    /// Lower end of the searched delays, seconds. Default 0 (a causal delay).
    pub min_s: f64,
    /// Upper end of the searched delays, seconds. Default `None`: 10 ms, but at most a
    /// quarter of `1 / df` (`df` the smallest line spacing), because for lines on a
    /// uniform grid `|D(tau)|` repeats with period `1 / (2 df)`.
    pub max_s: Option<f64>,
    /// Grid step of the coarse search, seconds. Default `None`: `1 / (32 f_max)`.
    pub grid_step_s: Option<f64>,
    /// Width of the final golden-section bracket, seconds. Default 1e-8 (10 ns).
    pub tolerance_s: f64,
    /// With a variance, weight each entry by its signal-to-noise fraction
    /// `|G|^2 / (|G|^2 + var)` as well as by `|G|`. Default `true`.
    pub use_variance: bool,
    /// Exponent `p` of the robust refinement (see the module documentation); 0 keeps the
    /// plain periodogram maximum. Default 16 (entries whose doubled phase is off by more
    /// than ~0.25 rad barely count).
    pub robust_power: u32,
}

impl Default for DelayConfig {
    fn default() -> Self {
        Self {
            min_s: 0.0,
            max_s: None,
            grid_step_s: None,
            tolerance_s: 1e-8,
            use_variance: true,
            robust_power: 16,
        }
    }
}

/// Which of the two branches of `|D|` the delay was found on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DelayPhaseKind {
    /// `G e^{j w tau}` is (nearly) real: displacement or acceleration per force.
    Real,
    /// `G e^{j w tau}` is (nearly) imaginary: velocity per force.
    Imaginary,
}

/// The result of [`estimate_delay`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DelayEstimate {
    /// The estimated delay, seconds (hold + computation + transport).
    pub tau_s: f64,
    /// Curvature (sandwich) standard deviation of `tau_s`, seconds, when the objective's
    /// second derivative is negative at the maximum. It reflects the scatter of the lines
    /// only, not the bias of the real-mode assumption (module documentation).
    pub std_s: Option<f64>,
    /// `|D(tau)| / n_lines`, in `[0, 1]`: 1 when every line's compensated FRF is exactly
    /// real (or imaginary). A low value (below ~0.3) means the data do not follow the
    /// real-mode assumption and the estimate should not be trusted.
    pub coherence: f64,
    /// Whether the compensated FRF is real or imaginary.
    pub kind: DelayPhaseKind,
    /// The searched range `[min, max]`, seconds.
    pub range_s: (f64, f64),
    /// Coarse grid step, seconds.
    pub grid_step_s: f64,
    /// Width of the final bracket, seconds (the resolution).
    pub resolution_s: f64,
    /// Number of lines used.
    pub n_lines: usize,
}

/// Grid points of the coarse delay search between exact recomputations of the phasors
/// (the others advance them by one complex product).
const COARSE_RESYNC: usize = 64;

/// The smallest number of usable lines (f > 0, non-zero response) [`estimate_delay`]
/// accepts: with fewer, the periodogram cannot separate a delay from the phase of the
/// response itself.
pub const MIN_DELAY_LINES: usize = 4;

/// Lines x entries from which the robust refinement of [`estimate_delay`] evaluates its
/// objective in blocks of lines on the rayon pool (about 50 evaluations; the 4 x 13 wafer
/// stage has 2e5 terms per evaluation, a 50 x 50 FRF with 4000 lines 1e7). Below it, one
/// thread and the sequential sum: a few SISO or 2 x 2 FRFs of some hundred lines.
const PARALLEL_TERMS: usize = 20_000;

/// Lines per block of the parallel robust objective (see [`PARALLEL_TERMS`]).
const PARALLEL_BLOCK_LINES: usize = 64;

/// Estimates the input/output delay of `data` with the delay periodogram of the squared
/// FRF (see the module documentation). Works on any band the caller selects; the default
/// range is `0 .. min(10 ms, 1 / (4 df))`.
///
/// Errors: fewer than [`MIN_DELAY_LINES`] lines with `f > 0` and a non-zero response;
/// an invalid range, grid step or tolerance.
pub fn estimate_delay(
    data: &(impl FrfDataset + ?Sized),
    cfg: &DelayConfig,
) -> Result<DelayEstimate, FrfError> {
    let (n, m) = (data.n_lines(), data.n_entries());
    // Per-line statistic s_k.
    let mut w = Vec::with_capacity(n);
    let mut s = Vec::with_capacity(n);
    // Per entry: the unit phasor g^2 / |g|^2 and its weight (normalised per line), all
    // lines one after the other (line `i` of `w` at `q.start[i]..q.start[i + 1]`), so
    // that the robust objective streams three contiguous arrays
    let mut q = UnitPhasors::with_capacity(n * m);
    let mut line = vec![C64::new(0.0, 0.0); m];
    let mut var = vec![0.0; m];
    let use_var = cfg.use_variance && data.has_variance();
    for k in 0..n {
        let f = data.freq_hz(k);
        if !(f.is_finite() && f > 0.0) {
            continue;
        }
        data.line_into(k, &mut line);
        if use_var {
            data.variance_line_into(k, &mut var);
        }
        let mut acc = C64::new(0.0, 0.0);
        let mut wsum = 0.0;
        let first = q.wt.len();
        for (e, g) in line.iter().enumerate() {
            let a = g.norm();
            if !(a.is_finite() && a > 0.0) {
                continue;
            }
            let mut wt = a;
            if use_var && var[e].is_finite() && var[e] > 0.0 {
                wt *= a * a / (a * a + var[e]);
            }
            // g^2 / |g|^2 is the unit phasor e^{2 j phase}.
            let ph = g * g / (a * a);
            acc += ph * wt;
            wsum += wt;
            q.re.push(ph.re);
            q.im.push(ph.im);
            q.wt.push(wt);
        }
        if wsum > 0.0 && acc.re.is_finite() && acc.im.is_finite() {
            w.push(TAU * f);
            s.push(acc / wsum);
            for x in &mut q.wt[first..] {
                *x /= wsum;
            }
            q.start.push(q.wt.len());
        } else {
            q.truncate(first);
        }
    }
    if w.len() < MIN_DELAY_LINES {
        return Err(FrfError::InvalidData {
            why: format!(
                "delay estimation needs at least {MIN_DELAY_LINES} lines with f > 0 and a \
                 non-zero response; the data have {} (of {n} lines)",
                w.len()
            ),
        });
    }
    let f_max = w.iter().copied().fold(0.0, f64::max) / TAU;
    let df_min = w
        .windows(2)
        .map(|p| (p[1] - p[0]) / TAU)
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let lo = cfg.min_s;
    let hi = match cfg.max_s {
        Some(h) => h,
        None => {
            let cap = if df_min.is_finite() {
                0.25 / df_min
            } else {
                f64::INFINITY
            };
            (10e-3_f64).min(cap).max(lo)
        }
    };
    if !(lo.is_finite() && hi.is_finite() && hi >= lo) {
        return Err(FrfError::invalid(
            "delay range",
            format!("{lo}..{hi} s"),
            "needs finite limits with min <= max",
        ));
    }
    let step = cfg.grid_step_s.unwrap_or(1.0 / (32.0 * f_max));
    if !(step.is_finite() && step > 0.0) {
        return Err(FrfError::invalid(
            "delay grid step",
            step,
            "must be finite and > 0",
        ));
    }
    if !(cfg.tolerance_s.is_finite() && cfg.tolerance_s > 0.0) {
        return Err(FrfError::invalid(
            "delay tolerance",
            cfg.tolerance_s,
            "must be finite and > 0",
        ));
    }
    let n_grid = ((hi - lo) / step).ceil() as usize + 1;
    if n_grid > 5_000_000 {
        return Err(FrfError::invalid(
            "delay range",
            format!("{lo}..{hi} s with step {step} s"),
            "more than 5e6 grid points; narrow the range or coarsen the step",
        ));
    }
    let d = |tau: f64| -> f64 {
        let mut acc = 0.0;
        for (wk, sk) in w.iter().zip(&s) {
            let (sn, cs) = (2.0 * wk * tau).sin_cos();
            acc += sk.re * cs - sk.im * sn;
        }
        acc
    };
    // Coarse grid. The phasors `e^{2 j w_k tau}` advance by `e^{2 j w_k step}` from one
    // grid point to the next: one complex product per line instead of a sine and a
    // cosine. They are recomputed exactly every `COARSE_RESYNC` points, so that the
    // rounding of the products never accumulates beyond that many steps.
    let mut best = (lo, f64::NEG_INFINITY);
    let (mut z_re, mut z_im) = (vec![0.0; w.len()], vec![0.0; w.len()]);
    let (r_re, r_im): (Vec<f64>, Vec<f64>) = w
        .iter()
        .map(|wk| {
            let (sn, cs) = (2.0 * wk * step).sin_cos();
            (cs, sn)
        })
        .unzip();
    for g in 0..n_grid {
        let tau = (lo + g as f64 * step).min(hi);
        let exact = g % COARSE_RESYNC == 0 || tau == hi;
        if exact {
            for (k, wk) in w.iter().enumerate() {
                (z_im[k], z_re[k]) = (2.0 * wk * tau).sin_cos();
            }
        } else {
            for k in 0..w.len() {
                let re = z_re[k] * r_re[k] - z_im[k] * r_im[k];
                z_im[k] = z_re[k] * r_im[k] + z_im[k] * r_re[k];
                z_re[k] = re;
            }
        }
        let acc: f64 = (0..w.len())
            .map(|k| s[k].re * z_re[k] - s[k].im * z_im[k])
            .sum();
        let v = acc.abs();
        if v > best.1 {
            best = (tau, v);
        }
    }
    // Golden-section search for the maximum of |D| inside [best - step, best + step].
    let (mut a, mut b) = ((best.0 - step).max(lo), (best.0 + step).min(hi));
    let gr = (5f64.sqrt() - 1.0) / 2.0;
    let mut x1 = b - gr * (b - a);
    let mut x2 = a + gr * (b - a);
    let (mut f1, mut f2) = (d(x1).abs(), d(x2).abs());
    let mut iter = 0;
    while b - a > cfg.tolerance_s && iter < 200 {
        iter += 1;
        if f1 >= f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - gr * (b - a);
            f1 = d(x1).abs();
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + gr * (b - a);
            f2 = d(x2).abs();
        }
    }
    let mut tau = 0.5 * (a + b);
    if d(tau).abs() < best.1 {
        tau = best.0;
    }
    let dv = d(tau);
    let sign = if dv >= 0.0 { 1.0 } else { -1.0 };
    let mut resolution = (b - a).max(0.0);
    // Robust refinement: maximise R(tau) = sum_k sum_e a_ke psi(x_ke(tau)) with
    // x = Re(sign q_ke e^{2 j w_k tau}) (the cosine of the entry's doubled phase error)
    // and the redescending psi(x) = max(x, 0)^p: an entry whose phase is off by more than
    // ~1/sqrt(p) rad (near its own resonance or anti-resonance) stops pulling the
    // estimate, which removes most of the bias of the plain periodogram.
    let p = cfg.robust_power;
    let mut std_s = None;
    if p > 0 {
        // (sum_k t_k^2, R) over the lines `lines` of `w` and `q`; each line's terms go
        // through small buffers in separate loops (rotation, power, sums), which the
        // compiler vectorises, instead of one loop per term with a branch and a power
        let block = |lines: std::ops::Range<usize>, tau: f64| -> (f64, f64) {
            let widest = lines
                .clone()
                .map(|k| q.start[k + 1] - q.start[k])
                .max()
                .unwrap_or(0);
            let (mut z_re, mut z_im) = (vec![0.0; widest], vec![0.0; widest]);
            let (mut x, mut pm1) = (vec![0.0; widest], vec![0.0; widest]);
            let mut acc = 0.0;
            let mut sum_t2 = 0.0;
            for k in lines {
                let wk = w[k];
                let rot = C64::from_polar(sign, 2.0 * wk * tau);
                let span = q.start[k]..q.start[k + 1];
                let len = span.len();
                let (re, im, wt) = (&q.re[span.clone()], &q.im[span.clone()], &q.wt[span]);
                // z = ph * rot; only Re z > 0 pulls (psi(x) = max(x, 0)^p)
                for i in 0..len {
                    z_re[i] = re[i] * rot.re - im[i] * rot.im;
                    z_im[i] = re[i] * rot.im + im[i] * rot.re;
                    x[i] = z_re[i].max(0.0);
                    pm1[i] = 1.0;
                }
                // pm1 = x^(p - 1) by repeated squaring over the whole line
                let mut e = p - 1;
                while e > 0 {
                    if e & 1 == 1 {
                        for (a, b) in pm1[..len].iter_mut().zip(&x[..len]) {
                            *a *= b;
                        }
                    }
                    e >>= 1;
                    if e > 0 {
                        for v in &mut x[..len] {
                            *v *= *v;
                        }
                    }
                }
                // R += sum wt x^p; d/dtau of x^p = p x^(p-1) * (-2 w Im z), summed
                // in four lanes
                let (mut a4, mut t4) = ([0.0; 4], [0.0; 4]);
                for i in 0..len {
                    let on = if z_re[i] > 0.0 { wt[i] * pm1[i] } else { 0.0 };
                    a4[i % 4] += on * z_re[i];
                    t4[i % 4] += on * z_im[i];
                }
                acc += (a4[0] + a4[1]) + (a4[2] + a4[3]);
                let t = ((t4[0] + t4[1]) + (t4[2] + t4[3])) * (p as f64 * -2.0 * wk);
                sum_t2 += t * t;
            }
            (sum_t2, acc)
        };
        let terms = q.wt.len();
        let n_lines = w.len();
        let robust = |tau: f64, out: Option<&mut (f64, f64)>| -> f64 {
            let (sum_t2, acc) = if terms >= PARALLEL_TERMS {
                // blocks of lines on the rayon pool, summed in their order (the same
                // result on every run)
                use rayon::prelude::*;
                let parts: Vec<(f64, f64)> = (0..n_lines.div_ceil(PARALLEL_BLOCK_LINES))
                    .into_par_iter()
                    .map(|b| {
                        let k0 = b * PARALLEL_BLOCK_LINES;
                        block(k0..(k0 + PARALLEL_BLOCK_LINES).min(n_lines), tau)
                    })
                    .collect();
                parts
                    .iter()
                    .fold((0.0, 0.0), |(a, b), (c, d)| (a + c, b + d))
            } else {
                block(0..n_lines, tau)
            };
            if let Some(o) = out {
                *o = (sum_t2, acc);
            }
            acc
        };
        let (mut ra, mut rb) = ((tau - step).max(lo), (tau + step).min(hi));
        // A fine scan first (the robust objective is narrower), then golden section.
        let n_fine = 32;
        let mut rbest = (tau, robust(tau, None));
        for i in 0..=n_fine {
            let t = ra + (rb - ra) * i as f64 / n_fine as f64;
            let v = robust(t, None);
            if v > rbest.1 {
                rbest = (t, v);
            }
        }
        let h = (rb - ra) / n_fine as f64;
        ra = (rbest.0 - h).max(lo);
        rb = (rbest.0 + h).min(hi);
        let mut x1 = rb - gr * (rb - ra);
        let mut x2 = ra + gr * (rb - ra);
        let (mut f1, mut f2) = (robust(x1, None), robust(x2, None));
        let mut iter = 0;
        while rb - ra > cfg.tolerance_s && iter < 200 {
            iter += 1;
            if f1 >= f2 {
                rb = x2;
                x2 = x1;
                f2 = f1;
                x1 = rb - gr * (rb - ra);
                f1 = robust(x1, None);
            } else {
                ra = x1;
                x1 = x2;
                f1 = f2;
                x2 = ra + gr * (rb - ra);
                f2 = robust(x2, None);
            }
        }
        let mut t_r = 0.5 * (ra + rb);
        if robust(t_r, None) < rbest.1 {
            t_r = rbest.0;
        }
        tau = t_r;
        resolution = (rb - ra).max(0.0);
        // Sandwich uncertainty: sqrt(sum_k t_k^2) / |R''|, R'' by central differences.
        let mut st = (0.0, 0.0);
        let r0 = robust(tau, Some(&mut st));
        let hh = (0.05 * step).max(1e-12);
        let r2 = (robust(tau + hh, None) - 2.0 * r0 + robust(tau - hh, None)) / (hh * hh);
        if r2 < 0.0 && st.0.is_finite() {
            std_s = Some(st.0.sqrt() / r2.abs());
        }
    } else {
        // Sandwich uncertainty on the branch sign * D.
        let mut sum_t2 = 0.0;
        let mut d2 = 0.0;
        for (wk, sk) in w.iter().zip(&s) {
            let rot = *sk * C64::from_polar(1.0, 2.0 * wk * tau) * sign;
            let t = 2.0 * wk * rot.im;
            sum_t2 += t * t;
            d2 += -4.0 * wk * wk * rot.re;
        }
        std_s = (d2 < 0.0).then(|| sum_t2.sqrt() / d2.abs());
    }
    let dv = d(tau);
    Ok(DelayEstimate {
        tau_s: tau,
        std_s,
        coherence: dv.abs() / w.len() as f64,
        kind: if sign > 0.0 {
            DelayPhaseKind::Real
        } else {
            DelayPhaseKind::Imaginary
        },
        range_s: (lo, hi),
        grid_step_s: step,
        resolution_s: resolution,
        n_lines: w.len(),
    })
}

/// The unit phasors `g^2 / |g|^2` of every usable entry of every usable line, with
/// their weights, stored line after line in three contiguous arrays.
struct UnitPhasors {
    re: Vec<f64>,
    im: Vec<f64>,
    wt: Vec<f64>,
    /// Line `i`'s entries are at `start[i]..start[i + 1]`.
    start: Vec<usize>,
}

impl UnitPhasors {
    fn with_capacity(terms: usize) -> Self {
        Self {
            re: Vec::with_capacity(terms),
            im: Vec::with_capacity(terms),
            wt: Vec::with_capacity(terms),
            start: vec![0],
        }
    }

    /// Drops the entries from `len` on (a line that turned out unusable).
    fn truncate(&mut self, len: usize) {
        self.re.truncate(len);
        self.im.truncate(len);
        self.wt.truncate(len);
    }
}

/// `data` with the delay `tau_s` removed: every line multiplied by `exp(+j w tau_s)`.
/// The variance is unchanged (the factor has modulus one); units, metadata, comments
/// and source are kept when `data` is an [`Frf`] (a view keeps its units). A non-finite
/// `tau_s` is no delay: the copy is returned unchanged.
pub fn compensate_delay(data: &(impl FrfDataset + ?Sized), tau_s: f64) -> Frf {
    let mut out = data.to_frf();
    if !tau_s.is_finite() {
        return out;
    }
    let w: Vec<f64> = out.omegas();
    out.scale_lines(|k| C64::from_polar(1.0, w[k] * tau_s));
    out
}
