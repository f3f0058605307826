//! [`MultiBandSk`]: Bayard's composite fit with Jue's tiered weights (section 2.3).
//!
//! With bands `Omega_1 < ... < Omega_B` (cut-offs given or from
//! [`super::auto_cut_offs`]) the model is `P = P_1 + ... + P_B`. Band `b`'s model is
//! the SK fit ([`SkInit`]) of the data minus the other bands' current models,
//!
//! `P_b = argmin sum_k w_k q_k^b^2 |G_k - sum_(c != b) P_c(w_k) - P(w_k)|^2`,
//!
//! with `w_k` the chain's data weight (inverse variance or eq. (27), computed once on the
//! data) and Jue's tiered weight, eq. (3): `q_k^b = Q_l` below the band, `1` in it,
//! `Q_h` above it (defaults `1e-1` and `1e-4`; Bayard's original weight is `Q_l = 1`,
//! `Q_h = 0`). The bands are fitted in turn, lowest first (Gauss-Seidel), and such
//! passes repeat until the total weighted error `sum w |G - P|^2` falls by less than
//! [`MultiBandConfig::pass_tol`] of itself (or rises); the pass with the smallest total
//! error is kept. Jue brings the bands in one at a time and retunes each band's order
//! and prewarp by hand (section 2.3.2); here every band is fitted from the first pass,
//! its order is chosen once by the F-test sweep of [`SkInit`] in the first pass (or
//! given) and kept in the later passes, and its bilinear map is prewarped at the
//! geometric mean of the band's first and last line.
//!
//! What each band may hold, so that the sum is one sensible model:
//!
//! - stable poles only (Jue: "we are only concerned with fitting a stable system with a
//!   stable model"): unstable SK poles are dropped, not reflected, and the band's
//!   residues are fitted again without them; the count is reported per band and pass;
//! - integrators (rigid body) only in the lowest band, whose lines see them (the other
//!   bands keep poles near the origin as ordinary poles);
//! - a feedthrough only in the highest band, where a plant's constant term shows.
//!
//! The composite in the model currency is the union of the bands' poles and residues
//! (pole pairs and real poles side by side), the lowest band's integrators, the highest
//! band's feedthrough, and the known factors (delay, hold, derivative order) that the
//! first band fit determined and every other band shares.

use super::auto::{auto_cut_offs, AutoBands, GapCandidate};
use super::spec::{assign_lines, BandSpec};
use crate::{fit_residues, BasisChoice, OrderScore, PoleSet, Prepared, SkConfig, SkError, SkInit};
use frf_data::cmif::{cmif, pick_peaks, Cmif};
use frf_data::{Convergence, DelayChoice, Estimator, Fit, Frf, FrfDataset, Weighting};
use realize::{FrfModel, Hold, KnownFactors, ModalModel, C64};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

/// Settings of [`MultiBandSk`], with documented defaults.
#[derive(Debug, Clone)]
pub struct MultiBandConfig {
    /// The bands. Default: [`BandSpec::Auto`].
    pub bands: BandSpec,
    /// `Q_l`, the tiered weight of the lines below a band (Jue, eq. (3)). Default: 1e-1.
    pub q_low: f64,
    /// `Q_h`, the tiered weight of the lines above a band. Default: 1e-4.
    pub q_high: f64,
    /// Passes over all bands, at most. Default: 8.
    pub max_passes: usize,
    /// The passes stop when the total weighted error falls by less than this fraction
    /// of itself in a pass ("until the total error stops falling"). Default: 1e-3.
    pub pass_tol: f64,
    /// The order of each band (one per band), or empty: chosen by the F-test sweep of
    /// [`SkInit`] in the first pass, starting at `2 p - 4` for `p` CMIF peaks in the
    /// band. Default: empty. With one band, `sk.order` is used as well.
    pub orders: Vec<usize>,
    /// SK iterations (after the Levy start) of each band fit, at most, with more than
    /// one band (one band keeps `sk.iter`): the band fits are repeated in every pass,
    /// and Jue's Table 2 reports 2 to 8 SK iterations per band and pass (on exact data
    /// the SK iterations oscillate rather than converge, Jue section 2.2.3). Default: 8.
    pub band_max_iter: usize,
    /// The automatic cut-offs. Default: [`AutoBands::default`].
    pub auto: AutoBands,
    /// A band with fewer lines is an error. Default: 8.
    pub min_band_lines: usize,
    /// The SK settings of every band fit (basis, SK weight and iterations, hold,
    /// delay, weighting, order sweep limits, feedthrough, rigid body; see the module
    /// documentation for what the bands change). Default: [`SkConfig::default`].
    pub sk: SkConfig,
}

impl Default for MultiBandConfig {
    fn default() -> Self {
        Self {
            bands: BandSpec::Auto,
            q_low: 1e-1,
            q_high: 1e-4,
            max_passes: 8,
            pass_tol: 1e-3,
            orders: Vec::new(),
            band_max_iter: 8,
            auto: AutoBands::default(),
            min_band_lines: 8,
            sk: SkConfig::default(),
        }
    }
}

impl MultiBandConfig {
    fn check(&self) -> Result<(), SkError> {
        for (name, q) in [("q_low", self.q_low), ("q_high", self.q_high)] {
            if !(0.0..=1.0).contains(&q) {
                return Err(SkError::config(
                    name,
                    q,
                    "the tiered weight must lie in [0, 1] (Jue, eq. (3))",
                ));
            }
        }
        if self.max_passes == 0 {
            return Err(SkError::config("max_passes", 0, "must be at least 1"));
        }
        if !(self.pass_tol.is_finite() && self.pass_tol >= 0.0) {
            return Err(SkError::config(
                "pass_tol",
                self.pass_tol,
                "must be finite and >= 0",
            ));
        }
        if self.auto.modes_per_band == 0 || self.auto.max_bands == 0 {
            return Err(SkError::config(
                "auto bands",
                format!(
                    "{} modes per band, {} bands at most",
                    self.auto.modes_per_band, self.auto.max_bands
                ),
                "both must be at least 1",
            ));
        }
        Ok(())
    }
}

/// What one band holds in the kept model.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BandReport {
    /// Lower edge, Hz (the lower cut-off; the first line for the lowest band).
    pub lo_hz: f64,
    /// Upper edge, Hz (the upper cut-off; the last line for the highest band).
    pub hi_hz: f64,
    /// Lines in the band.
    pub lines: usize,
    /// CMIF peaks in the band.
    pub cmif_peaks: usize,
    /// Number of SK poles of the band (before unstable ones were dropped).
    pub order: usize,
    /// Whether the order was given.
    pub order_given: bool,
    /// The order sweep of the first pass (empty when the order was given).
    pub sweep: Vec<OrderScore>,
    /// Prewarp frequency of the band's bilinear map, rad/s (`None`: the basis of the
    /// SK settings as it is).
    pub prewarp_rad_s: Option<f64>,
    /// Complex pole pairs kept.
    pub pairs: usize,
    /// Real poles kept.
    pub real_poles: usize,
    /// Integrators (lowest band only).
    pub integrators: usize,
    /// Whether the band holds the feedthrough (highest band only).
    pub feedthrough: bool,
    /// Unstable SK poles dropped from this band's model.
    pub dropped_unstable: usize,
    /// SK iterations of the band's last fit.
    pub sk_iterations: usize,
    /// Relative error of the composite on the band's lines, `||G - P||_F / ||G||_F`.
    pub rel_error: f64,
}

/// One pass over all bands.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PassReport {
    /// Total weighted cost `sum w |G - P|^2 / (2 L)` after the pass.
    pub weighted_cost: f64,
    /// Relative error `||G - P||_F / ||G||_F` over all lines and entries after the pass.
    pub rel_error: f64,
    /// SK iterations of each band's fit.
    pub sk_iterations: Vec<usize>,
    /// Unstable poles dropped in each band's fit.
    pub dropped_unstable: Vec<usize>,
    /// Band fits that failed in this pass (the band's previous model was kept).
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub failures: Vec<String>,
}

/// What [`MultiBandSk`] found.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BandsReport {
    /// The band specification (`auto`, `1`, or the cut-offs given).
    pub spec: String,
    /// The cut-offs used, Hz.
    pub cut_offs_hz: Vec<f64>,
    /// With `auto`: the cuts chosen and their scores (see [`super::auto_cut_offs`]).
    pub auto_cuts: Vec<GapCandidate>,
    /// CMIF peaks of the data (when the CMIF was needed).
    pub cmif_peaks: Option<usize>,
    /// `Q_l`.
    pub q_low: f64,
    /// `Q_h`.
    pub q_high: f64,
    /// Each band of the kept model.
    pub bands: Vec<BandReport>,
    /// Each pass.
    pub passes: Vec<PassReport>,
    /// The pass kept (1-based): the one with the smallest total weighted cost.
    pub kept_pass: usize,
    /// Why the passes stopped.
    pub stop: String,
    /// Total weighted cost of the kept model, `sum w |G - P|^2 / (2 L)`.
    pub weighted_cost: f64,
    /// Relative error of the kept model, `||G - P||_F / ||G||_F`.
    pub rel_error: f64,
    /// Poles of the composite (integrators included).
    pub order: usize,
    /// The delay divided out, seconds.
    pub delay_s: f64,
    /// The data weighting.
    pub weighting: String,
}

#[typetag::serde(name = "sk_bands")]
impl frf_data::LinkDetails for BandsReport {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// Bayard's multi-band composite SK fit (Jue, section 2.3; see the module
/// documentation).
#[derive(Debug, Clone, Default)]
pub struct MultiBandSk {
    /// Settings.
    pub config: MultiBandConfig,
}

/// One band of the plan.
struct Band {
    lines: Range<usize>,
    lo_hz: f64,
    hi_hz: f64,
    peaks: usize,
    /// `w_k q_k^b^2`.
    weights: Arc<Vec<f64>>,
}

/// One band's fit.
#[derive(Clone)]
struct BandFit {
    model: FrfModel,
    /// `vec(P_b)` at every line, factors included.
    response: Vec<C64>,
    order: usize,
    order_given: bool,
    sweep: Vec<OrderScore>,
    prewarp: Option<f64>,
    iterations: usize,
    dropped: usize,
}

/// The data as the passes use them.
struct Lines {
    freq_hz: Vec<f64>,
    omegas: Vec<f64>,
    ny: usize,
    nu: usize,
    g: Vec<C64>,
    w: Vec<f64>,
}

impl Lines {
    fn m(&self) -> usize {
        self.ny * self.nu
    }

    /// `(sum w |G - P|^2 / (2 L), ||G - P||_F / ||G||_F)` for `vec(P)` at every line.
    fn errors(&self, p: &[C64]) -> (f64, f64) {
        let (mut cost, mut e2, mut g2) = (0.0, 0.0, 0.0);
        for ((g, w), p) in self.g.iter().zip(&self.w).zip(p) {
            let d = (g - p).norm_sqr();
            cost += w * d;
            e2 += d;
            g2 += g.norm_sqr();
        }
        (
            cost / (2.0 * self.omegas.len() as f64),
            (e2 / g2.max(f64::MIN_POSITIVE)).sqrt(),
        )
    }

    /// `||G - P||_F / ||G||_F` on the lines `r`.
    fn band_error(&self, p: &[C64], r: &Range<usize>) -> f64 {
        let m = self.m();
        let span = r.start * m..r.end * m;
        let (e2, g2) = self.g[span.clone()]
            .iter()
            .zip(&p[span])
            .fold((0.0, 0.0), |(e, n), (g, p)| {
                (e + (g - p).norm_sqr(), n + g.norm_sqr())
            });
        (e2 / g2.max(f64::MIN_POSITIVE)).sqrt()
    }
}

/// The sum of modal models: the union of the poles and residues, the integrators and
/// feedthroughs added.
fn sum_models(parts: &[&ModalModel], ny: usize, nu: usize) -> ModalModel {
    let mut out = ModalModel::new(ny, nu);
    for m in parts {
        out.pairs.extend(m.pairs.iter().cloned());
        out.real_poles.extend(m.real_poles.iter().cloned());
        for (k, r) in m.rigid.iter().enumerate() {
            if out.rigid.len() <= k {
                out.rigid.push(faer::Mat::zeros(ny, nu));
            }
            out.rigid[k] += r;
        }
        out.feedthrough += &m.feedthrough;
    }
    out
}

impl MultiBandSk {
    /// An estimator with the given settings.
    pub fn new(config: MultiBandConfig) -> Self {
        Self { config }
    }

    /// Fits band `b` to `residual` (the data minus the other bands' models).
    #[allow(clippy::too_many_arguments)]
    fn fit_band(
        &self,
        lines: &Lines,
        bands: &[Band],
        b: usize,
        residual: Vec<C64>,
        delay: DelayChoice,
        order: Option<usize>,
        data_cmif: Option<&Arc<Cmif>>,
    ) -> Result<BandFit, SkError> {
        let base = &self.config.sk;
        let band = &bands[b];
        let nb = bands.len();
        let is_last = b + 1 == nb;
        let mut c = base.clone();
        c.weighting = Weighting::User(band.weights.clone());
        c.delay = delay;
        c.order = order;
        if nb > 1 {
            // the sweep starts from the band's own CMIF peaks
            c.start_from_peaks = false;
            c.min_order = base
                .min_order
                .max((2 * band.peaks).saturating_sub(4))
                .min(base.max_order);
            c.iter.max_iter = c.iter.max_iter.min(self.config.band_max_iter.max(1));
        }
        c.stabilize = false;
        c.feedthrough = base.feedthrough && is_last;
        if b > 0 {
            c.rigid_tol = 0.0;
        }
        if !matches!(delay, DelayChoice::Auto) {
            c.precomputed.delay = None;
        }
        // the data's CMIF serves one band (its residual is the data); the sweeps of
        // several bands start from the band's peaks instead
        c.precomputed.cmif = if nb == 1 { data_cmif.cloned() } else { None };
        let prewarp_ok = match (base.basis, base.hold) {
            (BasisChoice::Auto, Hold::Zoh { .. }) => false,
            (BasisChoice::Auto, _) | (BasisChoice::Bilinear { a: None }, _) => true,
            _ => false,
        };
        let prewarp = (nb > 1 && prewarp_ok).then(|| {
            let (lo, hi) = (
                lines.omegas[band.lines.start],
                lines.omegas[band.lines.end - 1],
            );
            (lo.max(f64::MIN_POSITIVE) * hi).sqrt()
        });
        if let Some(a) = prewarp {
            c.basis = BasisChoice::Bilinear { a: Some(a) };
        }
        let frf = Frf::new(lines.freq_hz.clone(), lines.ny, lines.nu, residual, None)?;
        let fit = SkInit::new(c.clone()).estimate(&frf, ())?;
        let mut model = fit.model;
        let modal = &model.modal;
        // poles, a pair counting two
        let dropped = 2 * modal.pairs.iter().filter(|p| p.pole.re >= 0.0).count()
            + modal.real_poles.iter().filter(|p| p.pole >= 0.0).count();
        if dropped > 0 {
            let set = PoleSet {
                pairs: modal
                    .pairs
                    .iter()
                    .filter(|p| p.pole.re < 0.0)
                    .map(|p| p.pole)
                    .collect(),
                reals: modal
                    .real_poles
                    .iter()
                    .filter(|p| p.pole < 0.0)
                    .map(|p| p.pole)
                    .collect(),
                integrators: modal.rigid.len(),
            };
            model.modal = if set.order() == 0 && !c.feedthrough {
                ModalModel::new(lines.ny, lines.nu)
            } else {
                let prep = Prepared::new(&frf, &c.weighting, &model.factors)?;
                fit_residues(&prep, &set, base.hold, c.feedthrough)?.0
            };
        }
        let response = model.freq_response(&lines.omegas)?.values;
        Ok(BandFit {
            model,
            response,
            order: fit.report.order,
            order_given: fit.report.order_given,
            sweep: fit.report.sweep,
            prewarp,
            iterations: fit.report.iterations,
            dropped,
        })
    }

    /// The band plan: cut-offs, lines, peaks and tiered weights of each band.
    fn plan<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        lines: &Lines,
        report: &mut BandsReport,
        cmif_out: &mut Option<Arc<Cmif>>,
    ) -> Result<Vec<Band>, SkError> {
        let cfg = &self.config;
        let c: Arc<Cmif> = match cfg.sk.precomputed.cmif_of(data) {
            Some(_) => cfg.sk.precomputed.cmif.clone().ok_or_else(|| {
                SkError::numerical("multi-band fit", "the precomputed CMIF vanished")
            })?,
            None => Arc::new(cmif(data)?),
        };
        let p = pick_peaks(&c, &cfg.sk.peaks);
        report.cmif_peaks = Some(p.len());
        if matches!(cfg.bands, BandSpec::Auto) {
            report.auto_cuts = auto_cut_offs(&c, &p, &cfg.auto);
        }
        let peaks: Vec<f64> = p.iter().map(|p| p.f_hz).collect();
        *cmif_out = Some(c);
        let cuts: Vec<f64> = match &cfg.bands {
            BandSpec::Auto => {
                // a cut exactly on a line puts that line in the upper band; a cut that
                // would leave a band with fewer than `min_band_lines` lines is left out
                // (its band merges with the next)
                let f = &lines.freq_hz;
                let min = cfg.min_band_lines.max(1);
                let mut kept: Vec<GapCandidate> = Vec::new();
                let mut start = 0;
                for c in &report.auto_cuts {
                    let at = f.partition_point(|&x| x < c.f_hz);
                    if at - start.min(at) >= min && f.len() - at >= min {
                        kept.push(c.clone());
                        start = at;
                    }
                }
                report.auto_cuts = kept;
                report.auto_cuts.iter().map(|c| c.f_hz).collect()
            }
            BandSpec::Single => Vec::new(),
            BandSpec::Cuts(c) => c.clone(),
        };
        report.cut_offs_hz = cuts.clone();
        let ranges = assign_lines(&lines.freq_hz, &cuts, cfg.min_band_lines)?;
        let nb = ranges.len();
        if !cfg.orders.is_empty() && cfg.orders.len() != nb {
            return Err(SkError::config(
                "orders",
                format!("{:?}", cfg.orders),
                format!("one order per band is needed: {nb} band(s)"),
            ));
        }
        if nb > 1 && cfg.sk.order.is_some() && cfg.orders.is_empty() {
            return Err(SkError::config(
                "order",
                cfg.sk.order.unwrap_or(0),
                format!(
                    "one order for {nb} bands is ambiguous: give one order per band, or \
                     none (each band's order is chosen by the sweep)"
                ),
            ));
        }
        let m = lines.m();
        Ok(ranges
            .into_iter()
            .enumerate()
            .map(|(b, r)| {
                let lo_hz = if b == 0 {
                    lines.freq_hz[0]
                } else {
                    cuts[b - 1]
                };
                let hi_hz = cuts
                    .get(b)
                    .copied()
                    .unwrap_or(lines.freq_hz[lines.freq_hz.len() - 1]);
                let n_peaks = peaks
                    .iter()
                    .filter(|&&f| f >= lines.freq_hz[r.start] && f <= lines.freq_hz[r.end - 1])
                    .count();
                let weights: Vec<f64> = (0..lines.omegas.len())
                    .flat_map(|k| {
                        let q = if k < r.start {
                            cfg.q_low
                        } else if k >= r.end {
                            cfg.q_high
                        } else {
                            1.0
                        };
                        (0..m).map(move |e| (k, e, q))
                    })
                    .map(|(k, e, q)| lines.w[k * m + e] * q * q)
                    .collect();
                Band {
                    lines: r,
                    lo_hz,
                    hi_hz,
                    peaks: n_peaks,
                    weights: Arc::new(weights),
                }
            })
            .collect())
    }
}

impl Estimator for MultiBandSk {
    type Model = FrfModel;
    type Start = ();
    type Report = BandsReport;
    type Error = SkError;

    fn estimate<D: FrfDataset + ?Sized + Sync>(
        &self,
        data: &D,
        _start: (),
    ) -> Result<Fit<FrfModel, BandsReport>, SkError> {
        let cfg = &self.config;
        let t0 = Instant::now();
        cfg.check()?;
        let l = data.n_lines();
        if l == 0 {
            return Err(SkError::OrderExceedsData {
                order: cfg.sk.order.unwrap_or(cfg.sk.min_order),
                lines: 0,
                max: 0,
            });
        }
        let weighting = cfg.sk.weighting.resolve(data);
        let lines = Lines {
            freq_hz: (0..l).map(|k| data.freq_hz(k)).collect(),
            omegas: data.omegas(),
            ny: data.ny(),
            nu: data.nu(),
            g: data.values_vec(),
            w: weighting.weights(data)?,
        };
        let m = lines.m();
        let mut report = BandsReport {
            spec: cfg.bands.to_string(),
            q_low: cfg.q_low,
            q_high: cfg.q_high,
            weighting: weighting.name().to_string(),
            ..Default::default()
        };
        let t = Instant::now();
        let mut data_cmif = None;
        let bands = self.plan(data, &lines, &mut report, &mut data_cmif)?;
        let t_plan = t.elapsed();
        let nb = bands.len();
        let mut messages = Vec::new();
        let mut orders: Vec<Option<usize>> = if cfg.orders.is_empty() {
            vec![if nb == 1 { cfg.sk.order } else { None }; nb]
        } else {
            cfg.orders.iter().map(|&n| Some(n)).collect()
        };
        // the weighted energy of the data, sum w |G|^2 / (2 L): the cost of the zero model
        let energy = lines.errors(&vec![C64::new(0.0, 0.0); l * m]).0;
        let mut fits: Vec<Option<BandFit>> = vec![None; nb];
        let mut factors: Option<KnownFactors> = None;
        let mut best: Option<(f64, usize, Vec<BandFit>)> = None;
        let mut convergence = Convergence::MaxIterations {
            limit: cfg.max_passes,
        };
        let mut stop = format!("{} passes (the limit)", cfg.max_passes);
        let zero = C64::new(0.0, 0.0);
        let t = Instant::now();
        for pass in 1..=cfg.max_passes {
            let mut pr = PassReport::default();
            for b in 0..nb {
                let band = &bands[b];
                cfg.sk.progress.step(
                    "sk bands",
                    pass,
                    Some(cfg.max_passes),
                    best.as_ref().map(|x| x.0),
                    format!("pass {pass}, band {} of {nb}", b + 1),
                );
                let mut residual = lines.g.clone();
                for (c, f) in fits.iter().enumerate() {
                    if let (true, Some(f)) = (c != b, f) {
                        residual
                            .iter_mut()
                            .zip(&f.response)
                            .for_each(|(r, p)| *r -= p);
                    }
                }
                let delay = match &factors {
                    None => cfg.sk.delay,
                    Some(f) if f.delay_fitted => DelayChoice::Start { seconds: f.delay_s },
                    Some(f) => DelayChoice::Fixed { seconds: f.delay_s },
                };
                match self.fit_band(
                    &lines,
                    &bands,
                    b,
                    residual,
                    delay,
                    orders[b],
                    data_cmif.as_ref(),
                ) {
                    Ok(f) => {
                        if factors.is_none() {
                            factors = Some(f.model.factors.clone());
                        }
                        orders[b] = Some(f.order);
                        pr.sk_iterations.push(f.iterations);
                        pr.dropped_unstable.push(f.dropped);
                        fits[b] = Some(f);
                    }
                    Err(e) if fits[b].is_some() => {
                        pr.sk_iterations.push(0);
                        pr.dropped_unstable.push(0);
                        pr.failures.push(format!(
                            "band {} ({:.4} .. {:.4} Hz): {e}; its previous model kept",
                            b + 1,
                            band.lo_hz,
                            band.hi_hz
                        ));
                    }
                    Err(e) => {
                        return Err(SkError::numerical(
                            &format!(
                                "band {} of {nb} ({:.4} .. {:.4} Hz, pass {pass})",
                                b + 1,
                                band.lo_hz,
                                band.hi_hz
                            ),
                            e.to_string(),
                        ))
                    }
                }
            }
            let mut total = vec![zero; l * m];
            for f in fits.iter().flatten() {
                total.iter_mut().zip(&f.response).for_each(|(t, p)| *t += p);
            }
            let (cost, rel) = lines.errors(&total);
            pr.weighted_cost = cost;
            pr.rel_error = rel;
            for fail in &pr.failures {
                messages.push(format!("pass {pass}: {fail}"));
            }
            report.passes.push(pr);
            let prev = best.as_ref().map(|x| x.0);
            if prev.is_none_or(|p| cost < p) {
                best = Some((cost, pass, fits.iter().flatten().cloned().collect()));
            }
            if nb == 1 {
                convergence = Convergence::Direct;
                stop = "one band: nothing to iterate".into();
                break;
            }
            if cost <= cfg.sk.exact_rel_cost * energy {
                convergence = Convergence::CostTolerance {
                    relative_change: 0.0,
                };
                stop = format!(
                    "pass {pass}: the total weighted error is below {:.1e} of the data's \
                     (the exact-fit level of the SK settings)",
                    cfg.sk.exact_rel_cost
                );
                break;
            }
            if let Some(p) = prev {
                let fall = (p - cost) / p.max(f64::MIN_POSITIVE);
                if fall < cfg.pass_tol {
                    convergence = Convergence::CostTolerance {
                        relative_change: fall.abs(),
                    };
                    stop = if fall < 0.0 {
                        format!(
                            "pass {pass}: the total error rose by {:.3e} (relative); the best \
                             pass is kept",
                            -fall
                        )
                    } else {
                        format!(
                            "pass {pass}: the total error fell by {fall:.3e} (relative), less \
                             than {:.1e}",
                            cfg.pass_tol
                        )
                    };
                    break;
                }
            }
        }
        let t_passes = t.elapsed();
        let (_, kept, kept_fits) = best.ok_or_else(|| {
            SkError::numerical("multi-band fit", "no pass completed (no band was fitted)")
        })?;
        let factors = factors.unwrap_or_default();
        let parts: Vec<&ModalModel> = kept_fits.iter().map(|f| &f.model.modal).collect();
        let modal = sum_models(&parts, lines.ny, lines.nu);
        let mut total = vec![zero; l * m];
        for f in &kept_fits {
            total.iter_mut().zip(&f.response).for_each(|(t, p)| *t += p);
        }
        let (cost, rel) = lines.errors(&total);
        report.kept_pass = kept;
        report.stop = stop;
        report.weighted_cost = cost;
        report.rel_error = rel;
        report.delay_s = factors.delay_s;
        report.order = 2 * modal.pairs.len() + modal.real_poles.len() + modal.rigid.len();
        for (b, (band, f)) in bands.iter().zip(&kept_fits).enumerate() {
            let mm = &f.model.modal;
            let br = BandReport {
                lo_hz: band.lo_hz,
                hi_hz: band.hi_hz,
                lines: band.lines.len(),
                cmif_peaks: band.peaks,
                order: f.order,
                order_given: f.order_given,
                sweep: f.sweep.clone(),
                prewarp_rad_s: f.prewarp,
                pairs: mm.pairs.len(),
                real_poles: mm.real_poles.len(),
                integrators: mm.rigid.len(),
                feedthrough: b + 1 == nb && cfg.sk.feedthrough,
                dropped_unstable: f.dropped,
                sk_iterations: f.iterations,
                rel_error: lines.band_error(&total, &band.lines),
            };
            messages.push(format!(
                "band {} ({:.4} .. {:.4} Hz, {} lines, {} CMIF peaks): order {} ({}), {} pole \
                 pairs, {} real poles{}{}; relative error in the band {:.3e}",
                b + 1,
                br.lo_hz,
                br.hi_hz,
                br.lines,
                br.cmif_peaks,
                br.order,
                if br.order_given { "given" } else { "swept" },
                br.pairs,
                br.real_poles,
                if br.integrators > 0 {
                    format!(", {} integrators", br.integrators)
                } else {
                    String::new()
                },
                if br.dropped_unstable > 0 {
                    format!(", {} unstable poles dropped", br.dropped_unstable)
                } else {
                    String::new()
                },
                br.rel_error
            ));
            report.bands.push(br);
        }
        messages.push(format!(
            "{nb} band(s), cut-offs {:?} Hz ({}); {} pass(es), pass {kept} kept: relative \
             error {rel:.4e}; {}",
            report.cut_offs_hz,
            report.spec,
            report.passes.len(),
            report.stop
        ));
        let model = FrfModel { modal, factors };
        model.validate()?;
        let mut fit = Fit {
            model,
            cost_history: report.passes.iter().map(|p| p.weighted_cost).collect(),
            iterations: report.passes.len(),
            convergence,
            timings: Vec::new(),
            estimator: "multi-band Sanathanan-Koerner composite (Bayard, Jue 2.3)".into(),
            messages,
            report,
        };
        fit.push_timing("bands", t_plan);
        fit.push_timing("passes", t_passes);
        fit.push_timing("total", t0.elapsed());
        Ok(fit)
    }
}
