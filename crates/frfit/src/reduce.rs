//! Model-order reduction of a model file (`frfit reduce`): balanced truncation of the
//! rational part's stable part ([`realize::balanced`]), with the rigid body, the
//! feedthrough and every known factor (delay, hold, derivative order, dynamics,
//! crosstalk) kept as they are, written back as a model file whose provenance holds the
//! Hankel singular values and the a-priori bound.
//!
//! The bound `2 sum(discarded Hankel singular values)` is on the H-infinity norm of the
//! difference of the rational parts (the continuous-time displacement model). The
//! delay has unit gain and a `sinc` hold at most 1, so it bounds the difference of the
//! full responses too; a derivative factor `(j w)^k` or a dynamics factor with gain
//! above one scales it by their gain.
//!
//! The model file stores its submodels, from which the response is rebuilt; the reduced
//! modal form is written as submodels exactly ([`additive_from_modal`]) in the file's own
//! time variable (continuous, or the exact zero-order-hold equivalent), and the result is
//! checked against the reduced model before it is returned.

use crate::FrfitError;
use additive_riv::{AdditiveModel, Domain, ModelFile, Submodel, SubmodelKind};
use faer::Mat;
use frf_data::ModelStructure;
use realize::balanced::{hinf_grid, max_sv_difference, BalancedReduction, HankelAnalysis};
use realize::{BalancedTruncation, FrfModel, ModalModel, C64};

/// Points per decade of the grid on which the H-infinity error is measured (plus the
/// points around every mode, see [`hinf_grid`]).
pub const MEASURE_PER_DECADE: usize = 200;

/// The model of a file and the Hankel singular values of its stable part.
#[derive(Debug, Clone)]
pub struct Analysed {
    /// The model exactly as the file rebuilds it.
    pub model: AdditiveModel,
    /// Its currency form (the rational part in modal form and the known factors).
    pub frf_model: FrfModel,
    /// Hankel singular values and state counts.
    pub hankel: HankelAnalysis,
}

/// What [`reduce_file`] produced.
#[derive(Debug, Clone)]
pub struct Reduced {
    /// The reduced model file (provenance with `hankel_singular_values`, `error_bound`).
    pub file: ModelFile,
    /// The reduction (reduced modal model, balanced state space, bound).
    pub reduction: BalancedReduction,
    /// `max sigma_max(P(j w) - P_r(j w))` of the rational parts on the measuring grid.
    pub measured_error: f64,
    /// Points of the measuring grid.
    pub grid_points: usize,
}

fn fit_err(what: &str) -> impl FnOnce(additive_riv::RivError) -> FrfitError + '_ {
    move |e| FrfitError::Fit {
        what: what.to_string(),
        why: e.to_string(),
    }
}

/// Rebuilds the model of `file` and computes the Hankel singular values of its stable
/// part.
pub fn analyse_file(file: &ModelFile) -> Result<Analysed, FrfitError> {
    let model = file.to_model().map_err(fit_err("model file"))?;
    let frf_model = model.to_frf_model_exact().map_err(fit_err("model file"))?;
    let hankel = BalancedTruncation::default().analyse(&frf_model.modal)?;
    Ok(Analysed {
        model,
        frf_model,
        hankel,
    })
}

/// Balanced truncation of the model in `file` to `order` states in all (rigid-body
/// states included; see [`realize::balanced`] for the orders that are refused), written
/// as a model file; `source` names the input in the provenance notes.
pub fn reduce_file(file: &ModelFile, order: usize, source: &str) -> Result<Reduced, FrfitError> {
    let a = analyse_file(file)?;
    let original = &a.frf_model.modal;
    let reduction = BalancedTruncation::default().reduce(original, order)?;
    let reduced_am = additive_from_modal(&a.model, &reduction.model)?;
    // the file form must give back the reduced model
    let back = reduced_am
        .to_frf_model_exact()
        .map_err(fit_err("reduced model"))?
        .modal;
    let check_grid = hinf_grid(&[original, &reduction.model], 50);
    let scale = reduction
        .hankel_singular_values
        .first()
        .copied()
        .unwrap_or(0.0)
        + original.feedthrough.norm_l2();
    let drift = max_sv_difference(&back, &reduction.model, &check_grid)?;
    if drift > 1e-9 * scale.max(f64::MIN_POSITIVE) || back.rigid.len() != original.rigid.len() {
        return Err(FrfitError::Fit {
            what: "reduced model file".into(),
            why: format!(
                "its submodels reproduce the reduced model only to {drift:.3e} (largest \
                 Hankel singular value {scale:.3e}): a reduced pole the file's time \
                 variable cannot hold (above the Nyquist frequency of the hold?)"
            ),
        });
    }
    let grid = hinf_grid(&[original, &reduction.model], MEASURE_PER_DECADE);
    let measured_error = max_sv_difference(original, &reduction.model, &grid)?;
    let mut provenance = file.provenance.clone();
    provenance.estimator = format!(
        "balanced truncation to order {order} of: {}",
        file.provenance.estimator
    );
    provenance.frfit_version = format!("{} (frfit reduce)", env!("CARGO_PKG_VERSION"));
    provenance.notes.push(format!(
        "reduced from {source} ({} states: {} rigid-body, kept exactly, and {} stable) to \
         {order} states by balanced truncation; a-priori H-infinity bound {:.6e}, measured \
         {measured_error:.6e} on {} points",
        a.hankel.rigid_order + a.hankel.stable_order,
        a.hankel.rigid_order,
        a.hankel.stable_order,
        reduction.error_bound,
        grid.len()
    ));
    provenance.hankel_singular_values = Some(reduction.hankel_singular_values.clone());
    provenance.error_bound = Some(reduction.error_bound);
    let out = ModelFile::from_model(
        &reduced_am,
        file.units.clone(),
        file.band_hz.map(|b| (b[0], b[1])),
        provenance,
    )
    .map_err(fit_err("reduced model file"))?;
    Ok(Reduced {
        file: out,
        reduction,
        measured_error,
        grid_points: grid.len(),
    })
}

/// `2^round(log2 x)`: a frequency scale by which dividing and multiplying is exact.
fn power_of_two_near(x: f64) -> f64 {
    if x.is_finite() && x > 0.0 {
        2f64.powi(x.log2().round() as i32)
    } else {
        1.0
    }
}

fn submodel(
    kind: SubmodelKind,
    integrators: usize,
    den: Vec<f64>,
    num_start: usize,
    num: Vec<Mat<f64>>,
    scale: f64,
) -> Submodel {
    Submodel {
        kind,
        integrators,
        den,
        num_start,
        num,
        scale,
        num_poly: vec![1.0],
        zoh_shape: false,
        bypass_factor: false,
    }
}

/// The additive model of `template` (its time variable, known factor, dynamics factors
/// and the submodels that bypass the factor) with the rational part replaced by the
/// continuous-time modal model `modal`, exactly:
///
/// - continuous time: the rigid body `sum_k R_k / s^k` as one submodel `B(x) / x^l`
///   with `B~_r = R_(l-r) / sigma^(l-r)` (`sigma` the template's rigid-body scale
///   rounded to a power of two, so that the coefficients come back bit for bit); a pair
///   `p` with residue `R` as `(B~_0 + B~_1 x) / (1 + 2 zeta x + x^2)`, `x = s / |p|`,
///   `B~_1 = 2 Re R / |p|`, `B~_0 = -2 Re(R conj p) / |p|^2`; a real pole as
///   `B~_0 / (1 + x)`, `x = s / |p|`, `B~_0 = R / |p|`;
/// - exact zero-order hold (`q = 1/z`, sample time `ts`): the images of the same terms,
///   `R / (s - p) -> R c q / (1 - z_p q)` with `z_p = e^(p ts)`, `c = (z_p - 1) / p`
///   (a pair: `q (2 Re(R c) - 2 Re(R c conj z_p) q) / (1 - 2 Re z_p q + |z_p|^2 q^2)`),
///   `R_1 / s -> R_1 ts q / (1 - q)` and
///   `R_1 / s + R_2 / s^2 -> q ((R_2 ts^2/2 + R_1 ts) + (R_2 ts^2/2 - R_1 ts) q) / (1 - q)^2`;
/// - the feedthrough as a constant submodel.
pub fn additive_from_modal(
    template: &AdditiveModel,
    modal: &ModalModel,
) -> Result<AdditiveModel, FrfitError> {
    let (ny, nu) = (modal.ny, modal.nu);
    if (ny, nu) != (template.ny(), template.nu()) {
        return Err(FrfitError::Fit {
            what: "reduced model".into(),
            why: format!(
                "is {ny}x{nu} but the model file is {}x{}",
                template.ny(),
                template.nu()
            ),
        });
    }
    let mut m = template.clone();
    let bypass: Vec<Submodel> = m
        .submodels
        .iter()
        .filter(|s| s.bypass_factor)
        .cloned()
        .collect();
    let rigid_scale = m
        .submodels
        .iter()
        .find(|s| s.integrators > 0 && !s.bypass_factor)
        .map_or(1.0, |s| s.scale);
    m.submodels.clear();
    let re = |x: &Mat<C64>, f: C64| Mat::from_fn(ny, nu, |i, j| (x[(i, j)] * f).re);
    let mut subs: Vec<Submodel> = Vec::new();
    let l = modal.rigid.len();
    match m.domain() {
        Domain::Continuous => {
            if l > 0 {
                let sigma = power_of_two_near(rigid_scale);
                let num = (0..l)
                    .map(|r| {
                        let f = sigma.powi((l - r) as i32);
                        Mat::from_fn(ny, nu, |i, j| modal.rigid[l - r - 1][(i, j)] / f)
                    })
                    .collect();
                subs.push(submodel(SubmodelKind::RigidBody, l, vec![], 0, num, sigma));
            }
            for p in &modal.pairs {
                let wn = p.pole.norm();
                let zeta = -p.pole.re / wn;
                let b1 = re(&p.residue, C64::new(2.0 / wn, 0.0));
                let b0 = re(&p.residue, -2.0 * p.pole.conj() / (wn * wn));
                subs.push(submodel(
                    SubmodelKind::Mode,
                    0,
                    vec![2.0 * zeta, 1.0],
                    0,
                    vec![b0, b1],
                    wn,
                ));
            }
            for p in &modal.real_poles {
                let w = -p.pole;
                let b0 = Mat::from_fn(ny, nu, |i, j| p.residue[(i, j)] / w);
                subs.push(submodel(
                    SubmodelKind::General,
                    0,
                    vec![1.0],
                    0,
                    vec![b0],
                    w,
                ));
            }
        }
        Domain::ZohDiscrete { ts } => {
            let r = |k: usize| &modal.rigid[k];
            match l {
                0 => {}
                1 => subs.push(submodel(
                    SubmodelKind::RigidBody,
                    1,
                    vec![],
                    1,
                    vec![Mat::from_fn(ny, nu, |i, j| r(0)[(i, j)] * ts)],
                    1.0,
                )),
                2 => {
                    let h = ts * ts / 2.0;
                    let n1 = Mat::from_fn(ny, nu, |i, j| r(1)[(i, j)] * h + r(0)[(i, j)] * ts);
                    let n2 = Mat::from_fn(ny, nu, |i, j| r(1)[(i, j)] * h - r(0)[(i, j)] * ts);
                    subs.push(submodel(
                        SubmodelKind::RigidBody,
                        2,
                        vec![],
                        1,
                        vec![n1, n2],
                        1.0,
                    ));
                }
                _ => {
                    return Err(FrfitError::Fit {
                        what: "reduced model".into(),
                        why: "the exact-hold model file holds at most 2 integrators".into(),
                    })
                }
            }
            let zoh = |p: C64| {
                let zp = (p * ts).exp();
                (zp, (zp - 1.0) / p)
            };
            for p in &modal.pairs {
                let (zp, c) = zoh(p.pole);
                let n1 = re(&p.residue, 2.0 * c);
                let n2 = re(&p.residue, -2.0 * c * zp.conj());
                subs.push(submodel(
                    SubmodelKind::Mode,
                    0,
                    vec![-2.0 * zp.re, zp.norm_sqr()],
                    1,
                    vec![n1, n2],
                    1.0,
                ));
            }
            for p in &modal.real_poles {
                let (zp, c) = zoh(C64::new(p.pole, 0.0));
                let n1 = Mat::from_fn(ny, nu, |i, j| p.residue[(i, j)] * c.re);
                subs.push(submodel(
                    SubmodelKind::General,
                    0,
                    vec![-zp.re],
                    1,
                    vec![n1],
                    1.0,
                ));
            }
        }
    }
    let has_d = (0..ny).any(|i| (0..nu).any(|j| modal.feedthrough[(i, j)] != 0.0));
    if has_d {
        subs.push(submodel(
            SubmodelKind::Feedthrough,
            0,
            vec![],
            0,
            vec![modal.feedthrough.clone()],
            1.0,
        ));
    }
    for s in subs.into_iter().chain(bypass) {
        m.push_submodel(s).map_err(fit_err("reduced model"))?;
    }
    Ok(m)
}
