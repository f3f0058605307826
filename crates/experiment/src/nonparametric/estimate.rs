//! The nonparametric MIMO FRF estimate from periodic spectra and its variances.
//!
//! Per realization `r` and line `k`:
//! - period means `U_bar = mean_p U_p`, `Y_bar = mean_p Y_p` (McKelvey, eq. (21): the
//!   average over periods is a consistent estimate of the noise-free periodic signals),
//!   columns = experiments;
//! - `G_r = Y_bar U_bar^-1` (`Y_bar U_bar^+` with more experiments than inputs): the
//!   indirect closed-loop estimate `T_yr T_ur^-1` with `T_yr = Y_bar R^-1`,
//!   `T_ur = U_bar R^-1`, errors-in-variables (noise on both `u` and `y` is allowed);
//!   for one input and one experiment it is `mean_p(Y_p) / mean_p(U_p)`;
//! - the residuals `E_p = Y_p - G_r U_p` are the output disturbance spectra per period
//!   (`y = G u + v` holds in closed loop too); their sample covariance over periods,
//!   `C_e = sum_p (E_p - E_bar)(E_p - E_bar)^H / (P - 1)`, gives the noise variance of
//!   `G_r` by linearisation: `var(G_r[i, j]) = sum_e |W[e, j]|^2 C_e[i, i] / P` with
//!   `W = U_bar^-1`.
//!
//! Over realizations: `G = mean_r G_r`; the noise variance of `G` is
//! `sum_r var(G_r) / R^2`; the total variance is the sample variance of `G_r` over
//! realizations divided by `R` (it also holds the stochastic nonlinear distortions that
//! differ between random-phase realizations). Their difference is the nonlinear
//! distortion level. The output disturbance covariance `C_v(w_k)` is the pooled `C_e`
//! (the covariance of one period's disturbance DFT; divide by `P` for the period mean,
//! cf. eq. (25) of Oomen and Bosgra).
//!
//! The `_var` of the returned [`Frf`] is the total variance when `R >= 2`, otherwise the
//! noise variance (`P >= 2`), otherwise absent.

use super::small::{invert, matmul, norm1};
use super::{PeriodicSpectra, RealizationSpectra};
use frf_data::{Frf, FrfError, C64};
use rayon::prelude::*;

/// Settings of the estimator.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorConfig {
    /// Smallest accepted reciprocal condition number (1-norm) of the input matrix
    /// `U_bar` at a line; below it the estimate fails with [`FrfError::SingularInput`]
    /// (default `1e-12`).
    pub min_rcond: f64,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self { min_rcond: 1e-12 }
    }
}

/// The result: the FRF (with `_var`), the separate variances and the disturbance
/// covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct NonparametricFrf {
    /// `G` with its variance (total when `R >= 2`, else noise).
    pub frf: Frf,
    /// Noise variance of `G` from the period-to-period spread (`P >= 2`), layout of
    /// [`Frf::values`].
    pub noise_variance: Option<Vec<f64>>,
    /// Total variance of `G` from the realization spread (`R >= 2`).
    pub total_variance: Option<Vec<f64>>,
    /// Output disturbance covariance `C_v` per line (`ny x ny` column-major, line after
    /// line), covariance of one period's disturbance DFT (unnormalised DFT); `P >= 2`.
    pub disturbance_covariance: Option<Vec<C64>>,
    /// Number of periods averaged.
    pub periods: usize,
    /// Number of realizations averaged.
    pub realizations: usize,
    /// Number of experiments.
    pub n_experiments: usize,
}

impl NonparametricFrf {
    /// Total minus noise variance per entry and line (layout of [`Frf::values`]): the
    /// variance of the stochastic nonlinear distortions. Negative values are estimation
    /// noise (both variances are estimates). Needs `P >= 2` and `R >= 2`.
    pub fn nonlinear_distortion(&self) -> Option<Vec<f64>> {
        let (t, n) = (self.total_variance.as_ref()?, self.noise_variance.as_ref()?);
        Some(t.iter().zip(n).map(|(a, b)| a - b).collect())
    }

    /// Per line: the mean over entries of total / noise variance (1 when the data are
    /// linear, larger with nonlinear distortions). Needs `P >= 2` and `R >= 2`.
    pub fn distortion_ratio_per_line(&self) -> Option<Vec<f64>> {
        let (t, n) = (self.total_variance.as_ref()?, self.noise_variance.as_ref()?);
        let m = self.frf_entries();
        Some(
            t.chunks(m)
                .zip(n.chunks(m))
                .map(|(a, b)| {
                    let s: f64 = a
                        .iter()
                        .zip(b)
                        .map(|(x, y)| if *y > 0.0 { x / y } else { 1.0 })
                        .sum();
                    s / m as f64
                })
                .collect(),
        )
    }

    /// The disturbance covariance `C_v` at line `k` (`ny x ny`, column-major).
    pub fn disturbance_at(&self, k: usize) -> Option<&[C64]> {
        let ny = frf_data::FrfDataset::ny(&self.frf);
        self.disturbance_covariance
            .as_ref()
            .map(|c| &c[k * ny * ny..(k + 1) * ny * ny])
    }

    fn frf_entries(&self) -> usize {
        frf_data::FrfDataset::n_entries(&self.frf)
    }
}

/// What one realization gives at one line.
struct LineResult {
    g: Vec<C64>,
    noise: Vec<f64>,
    cv: Vec<C64>,
}

/// Streaming estimator: feed realizations one at a time with [`Accumulator::add`] (the
/// simulator does, so the spectra of all realizations never have to be in memory at
/// once), then [`Accumulator::finish`].
#[derive(Debug, Clone)]
pub struct Accumulator {
    freq_hz: Vec<f64>,
    ny: usize,
    nu: usize,
    n_experiments: usize,
    config: EstimatorConfig,
    count: usize,
    periods: Option<usize>,
    mean: Vec<C64>,
    m2: Vec<f64>,
    noise_sum: Vec<f64>,
    cv_sum: Vec<C64>,
    has_noise: bool,
}

impl Accumulator {
    /// An empty accumulator for spectra at `freq_hz` with `n_experiments` experiments.
    pub fn new(
        freq_hz: Vec<f64>,
        ny: usize,
        nu: usize,
        n_experiments: usize,
        config: EstimatorConfig,
    ) -> Result<Self, FrfError> {
        if freq_hz.is_empty() {
            return Err(FrfError::invalid(
                "excited lines",
                "none",
                "there are no excited lines to estimate the FRF at",
            ));
        }
        if ny == 0 || nu == 0 {
            return Err(FrfError::invalid(
                "dimensions",
                format!("{ny}x{nu}"),
                "need at least one input and one output",
            ));
        }
        if n_experiments < nu {
            return Err(FrfError::SingularInput {
                line: 0,
                freq_hz: freq_hz[0],
                realization: 0,
                rcond: 0.0,
                why: format!(
                    "{n_experiments} experiment(s) cannot identify {nu} inputs: the input \
                     matrix has rank <= {n_experiments}"
                ),
            });
        }
        if !(config.min_rcond.is_finite() && config.min_rcond >= 0.0) {
            return Err(FrfError::invalid(
                "min_rcond",
                config.min_rcond,
                "must be finite and >= 0",
            ));
        }
        let n = freq_hz.len();
        Ok(Self {
            freq_hz,
            ny,
            nu,
            n_experiments,
            config,
            count: 0,
            periods: None,
            mean: vec![C64::new(0.0, 0.0); n * ny * nu],
            m2: vec![0.0; n * ny * nu],
            noise_sum: vec![0.0; n * ny * nu],
            cv_sum: vec![C64::new(0.0, 0.0); n * ny * ny],
            has_noise: true,
        })
    }

    /// Adds one realization (all experiments and periods).
    pub fn add(&mut self, rs: &RealizationSpectra) -> Result<(), FrfError> {
        let (ny, nu, ne) = (self.ny, self.nu, self.n_experiments);
        let n = self.freq_hz.len();
        if rs.ny() != ny || rs.nu() != nu || rs.n_lines() != n || rs.n_experiments() != ne {
            return Err(FrfError::Dimension {
                what: format!("realization {}", self.count),
                expected: format!("{ny}x{nu}, {n} lines, {ne} experiments"),
                got: format!(
                    "{}x{}, {} lines, {} experiments",
                    rs.ny(),
                    rs.nu(),
                    rs.n_lines(),
                    rs.n_experiments()
                ),
            });
        }
        let p = rs.periods();
        match self.periods {
            None => self.periods = Some(p),
            Some(p0) if p0 != p => {
                return Err(FrfError::Dimension {
                    what: format!("periods of realization {}", self.count),
                    expected: p0.to_string(),
                    got: p.to_string(),
                })
            }
            _ => {}
        }
        if p < 2 {
            self.has_noise = false;
        }
        let r = self.count;
        let min_rcond = self.config.min_rcond;
        let freq = &self.freq_hz;
        // the lines in parallel, the error of the lowest failing line (a parallel collect
        // into a `Result` stops at whichever failing line a thread reaches first)
        let per_line: Vec<Result<LineResult, _>> = (0..n)
            .into_par_iter()
            .map(|k| line_estimate(rs, k, min_rcond).map_err(|(rc, why)| (k, rc, why)))
            .collect();
        let results: Vec<LineResult> = per_line
            .into_iter()
            .collect::<Result<Vec<_>, _>>()
            .map_err(|(k, rcond, why)| FrfError::SingularInput {
                line: k,
                freq_hz: freq[k],
                realization: r,
                rcond,
                why,
            })?;
        let m = ny * nu;
        self.count += 1;
        let cnt = self.count as f64;
        for (k, lr) in results.into_iter().enumerate() {
            for e in 0..m {
                let idx = k * m + e;
                // Welford update of the mean and the sum of squared deviations
                let delta = lr.g[e] - self.mean[idx];
                self.mean[idx] += delta / cnt;
                let delta2 = lr.g[e] - self.mean[idx];
                self.m2[idx] += (delta.conj() * delta2).re;
                self.noise_sum[idx] += lr.noise[e];
            }
            for (i, v) in lr.cv.iter().enumerate() {
                self.cv_sum[k * ny * ny + i] += *v;
            }
        }
        Ok(())
    }

    /// Number of realizations added so far.
    pub fn count(&self) -> usize {
        self.count
    }

    /// The estimate over the realizations added.
    pub fn finish(self) -> Result<NonparametricFrf, FrfError> {
        if self.count == 0 {
            return Err(FrfError::invalid(
                "realizations",
                0,
                "no realization was added to the estimator",
            ));
        }
        let rr = self.count as f64;
        let periods = self.periods.unwrap_or(0);
        let noise = self.has_noise.then(|| {
            self.noise_sum
                .iter()
                .map(|v| v / (rr * rr))
                .collect::<Vec<f64>>()
        });
        let total = (self.count >= 2).then(|| {
            self.m2
                .iter()
                .map(|v| v / (rr - 1.0) / rr)
                .collect::<Vec<f64>>()
        });
        let cv = self
            .has_noise
            .then(|| self.cv_sum.iter().map(|v| v / rr).collect::<Vec<C64>>());
        let var = total.clone().or_else(|| noise.clone());
        let mut frf = Frf::new(self.freq_hz, self.ny, self.nu, self.mean, var)?;
        // with several realizations `var` is the total variance; its noise part goes
        // beside it (`_var_noise`), so that `var - var_noise` is the nonlinear part
        if total.is_some() {
            frf = frf.with_noise_variance(noise.clone())?;
        }
        frf.metadata.insert("periods".into(), periods.to_string());
        frf.metadata
            .insert("realizations".into(), self.count.to_string());
        frf.metadata
            .insert("experiments".into(), self.n_experiments.to_string());
        frf.metadata.insert(
            "variance".into(),
            if total.is_some() {
                "total (realization spread / R)"
            } else if noise.is_some() {
                "noise (period spread)"
            } else {
                "none"
            }
            .into(),
        );
        Ok(NonparametricFrf {
            frf,
            noise_variance: noise,
            total_variance: total,
            disturbance_covariance: cv,
            periods,
            realizations: self.count,
            n_experiments: self.n_experiments,
        })
    }
}

/// `G_r`, its noise variance and the disturbance covariance of one realization at line
/// `k` (see the module documentation). Errors carry the reciprocal condition and why.
fn line_estimate(
    rs: &RealizationSpectra,
    k: usize,
    min_rcond: f64,
) -> Result<LineResult, (f64, String)> {
    let (ny, nu, ne, np) = (rs.ny(), rs.nu(), rs.n_experiments(), rs.periods());
    let inv_p = 1.0 / np as f64;
    // period means, column per experiment
    let mut ub = vec![C64::new(0.0, 0.0); nu * ne];
    let mut yb = vec![C64::new(0.0, 0.0); ny * ne];
    for e in 0..ne {
        for p in 0..np {
            for (j, v) in rs.input_at(e, p, k).iter().enumerate() {
                ub[e * nu + j] += *v;
            }
            for (i, v) in rs.output_at(e, p, k).iter().enumerate() {
                yb[e * ny + i] += *v;
            }
        }
    }
    ub.iter_mut().chain(yb.iter_mut()).for_each(|v| *v *= inv_p);
    // W = U_bar^-1 (ne == nu) or U_bar^+ = U_bar^H (U_bar U_bar^H)^-1 (ne > nu): ne x nu
    let (w, rcond) = if ne == nu {
        match invert(&ub, nu) {
            Some(inv) => {
                let rc = 1.0 / (norm1(&ub, nu, nu) * norm1(&inv, nu, nu));
                (inv, rc)
            }
            None => (Vec::new(), 0.0),
        }
    } else {
        let uh: Vec<C64> = (0..nu)
            .flat_map(|j| (0..ne).map(move |e| (e, j)))
            .map(|(e, j)| ub[e * nu + j].conj())
            .collect(); // ne x nu column-major: uh[j * ne + e] = conj(ub[e, j])
        let gram = matmul(&ub, &uh, nu, ne, nu);
        match invert(&gram, nu) {
            Some(ginv) => {
                let rc = 1.0 / (norm1(&gram, nu, nu) * norm1(&ginv, nu, nu));
                (matmul(&uh, &ginv, ne, nu, nu), rc.sqrt())
            }
            None => (Vec::new(), 0.0),
        }
    };
    if !(rcond.is_finite() && rcond >= min_rcond) || w.is_empty() {
        return Err((
            if rcond.is_finite() { rcond } else { 0.0 },
            "the input spectra of the experiments are (nearly) linearly dependent: every \
             input must be excited by an independent experiment"
                .into(),
        ));
    }
    let g = matmul(&yb, &w, ny, ne, nu);
    let mut noise = vec![0.0; ny * nu];
    let mut cv = vec![C64::new(0.0, 0.0); ny * ny];
    if np >= 2 {
        let mut resid = vec![C64::new(0.0, 0.0); np * ny];
        let mut ebar = vec![C64::new(0.0, 0.0); ny];
        for e in 0..ne {
            ebar.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
            for p in 0..np {
                let u = rs.input_at(e, p, k);
                let y = rs.output_at(e, p, k);
                for i in 0..ny {
                    let mut s = y[i];
                    for j in 0..nu {
                        s -= g[j * ny + i] * u[j];
                    }
                    resid[p * ny + i] = s;
                    ebar[i] += s * inv_p;
                }
            }
            let scale = 1.0 / (np as f64 - 1.0);
            for a in 0..ny {
                for b in 0..ny {
                    let mut s = C64::new(0.0, 0.0);
                    for p in 0..np {
                        s += (resid[p * ny + a] - ebar[a]) * (resid[p * ny + b] - ebar[b]).conj();
                    }
                    cv[b * ny + a] += s * scale / ne as f64;
                    if a == b {
                        let c_ii = s.re * scale;
                        for j in 0..nu {
                            noise[j * ny + a] += w[j * ne + e].norm_sqr() * c_ii * inv_p;
                        }
                    }
                }
            }
        }
    }
    Ok(LineResult { g, noise, cv })
}

/// Estimates the FRF from all realizations of `spectra` (see the module documentation).
pub fn estimate(
    spectra: &PeriodicSpectra,
    config: &EstimatorConfig,
) -> Result<NonparametricFrf, FrfError> {
    let mut acc = Accumulator::new(
        spectra.freq_hz.clone(),
        spectra.ny,
        spectra.nu,
        spectra.n_experiments(),
        config.clone(),
    )?;
    for rs in &spectra.realizations {
        acc.add(rs)?;
    }
    let mut out = acc.finish()?;
    out.frf.units = spectra.units.clone();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::FrfDataset;
    use proptest::prelude::*;

    /// Noise-free spectra `Y_p = G U_p` with inputs that change from period to period.
    fn spectra(
        g: &[C64],
        ny: usize,
        nu: usize,
        ne: usize,
        np: usize,
        u: &[C64],
    ) -> RealizationSpectra {
        let nl = 1;
        let mut input = Vec::new();
        let mut output = Vec::new();
        for e in 0..ne {
            for p in 0..np {
                let up: Vec<C64> = (0..nu)
                    .map(|j| {
                        u[e * nu + j] * (1.0 + 0.1 * p as f64)
                            + C64::new(0.01 * (p * j) as f64, 0.0)
                    })
                    .collect();
                for i in 0..ny {
                    output.push((0..nu).map(|j| g[j * ny + i] * up[j]).sum::<C64>());
                }
                input.extend(up);
            }
        }
        // output was pushed per (e, p) with ny values: layout [e][p][line][ny] with one line
        RealizationSpectra::new(ne, np, nl, ny, nu, input, output, None).unwrap()
    }

    proptest! {
        #[test]
        fn noise_free_data_give_the_frf_exactly(
            ny in 1usize..4, nu in 1usize..4, extra in 0usize..2, np in 2usize..4,
            vals in proptest::collection::vec(-1.0f64..1.0, 80),
        ) {
            let ne = nu + extra;
            let g: Vec<C64> = (0..ny * nu).map(|i| C64::new(vals[2 * i], vals[2 * i + 1])).collect();
            // diagonally dominant inputs: well conditioned
            let u: Vec<C64> = (0..ne * nu)
                .map(|i| {
                    let (e, j) = (i / nu, i % nu);
                    let d = if e == j { 3.0 } else { 0.0 };
                    C64::new(d + vals[40 + i % 40] * 0.5, vals[(i * 7) % 40] * 0.5)
                })
                .collect();
            let rs = spectra(&g, ny, nu, ne, np, &u);
            let mut acc = Accumulator::new(vec![1.0], ny, nu, ne, EstimatorConfig::default()).unwrap();
            acc.add(&rs).unwrap();
            let est = acc.finish().unwrap();
            for i in 0..ny {
                for j in 0..nu {
                    let d = (est.frf.value(0, i, j) - g[j * ny + i]).norm();
                    prop_assert!(d < 1e-12, "entry ({i}, {j}) off by {d}");
                    prop_assert!(est.frf.variance(0, i, j).unwrap() < 1e-24);
                }
            }
        }
    }

    #[test]
    fn siso_estimate_is_the_ratio_of_period_means_with_the_eiv_variance() {
        // G = mean(Y) / mean(U); var = sum |Y_p - G U_p|^2 / (P (P - 1) |mean U|^2)
        let u = [C64::new(1.0, 0.5), C64::new(1.1, 0.4), C64::new(0.9, 0.55)];
        let y = [C64::new(2.0, 0.0), C64::new(2.3, -0.1), C64::new(1.8, 0.2)];
        let rs = RealizationSpectra::new(1, 3, 1, 1, 1, u.to_vec(), y.to_vec(), None).unwrap();
        let mut acc = Accumulator::new(vec![5.0], 1, 1, 1, EstimatorConfig::default()).unwrap();
        acc.add(&rs).unwrap();
        let est = acc.finish().unwrap();
        let (um, ym) = (u.iter().sum::<C64>() / 3.0, y.iter().sum::<C64>() / 3.0);
        let g = ym / um;
        let v: f64 = u
            .iter()
            .zip(&y)
            .map(|(a, b)| (b - g * a).norm_sqr())
            .sum::<f64>()
            / (3.0 * 2.0)
            / um.norm_sqr();
        assert!((est.frf.value(0, 0, 0) - g).norm() < 1e-15);
        assert!((est.frf.variance(0, 0, 0).unwrap() - v).abs() < 1e-12 * v);
        assert!(est.total_variance.is_none());
        assert_eq!(est.frf.metadata["variance"], "noise (period spread)");
    }
}
