//! The model validation problems of Oomen and Bosgra, "Well-posed model uncertainty
//! estimation by design of validation experiments", at one frequency line: the decision
//! problem (FDMVDP, Problem 1) by the generalized structured singular value of the
//! implicit LFT (eqs. (26)-(29), Proposition 12), and the optimisation problem (FDMVOP,
//! Problem 2), the smallest uncertainty norm `gamma` that does not invalidate the model,
//! by bisection on `gamma`.
//!
//! **The uncertain model (2).** `z = F_u(M^, Delta_u) w + v` with the interconnection
//! `M^ = [M11 M12; M21 M22]`: `M22` is the nominal model `P^` (`ny x nu`) at the line and
//! [`UncertaintyModel`] holds `M11`, `M12`, `M21` and the structure of `Delta_u`
//! (`sigma_max(Delta_u) <= gamma`, eq. (5)). [`UncertaintyModel::additive`] is the default
//! (`P^ + Delta_u`, the paper's Section 6), [`UncertaintyModel::output_multiplicative`]
//! (`(I + Delta_u) P^`) shows that the LFT is general: dual-Youla structures only need
//! their `M11`, `M12`, `M21`.
//!
//! **Prop. 12.** With the disturbance model `T_V Delta_v V~ 1` ([`DisturbanceModel`]),
//! the consistency equation `0 = Z_m - F_u(M^, Delta_u) W - T_V Delta_v V~ 1` is the
//! implicit LFT (28): `M_bar11 = diag(0, gamma M11)`, `M_bar12 = [V~ 1; -M12 W]`,
//! `M_bar21 = [-T_V, gamma M21]`, `M_bar22 = E_nom = Z_m - M22 W`, with
//! `Delta_bar = diag(delta_v1, ..., delta_v,ny, Delta_u)`. The model is not invalidated at
//! `gamma` iff `mu(M_bar11 - M_bar12 X22 M_bar21, M_bar21 - M_bar22 X22 M_bar21) >= 1`
//! with `X22 = E_nom^H / |E_nom|^2` (a left inverse of `E_nom`); see [`crate::mu`].
//!
//! **Bisection ([`min_gamma`]).** `gamma = 0` is tested first (a model the disturbance
//! alone explains). Otherwise `[lo, hi]` starts at `lo = 0` and `hi` the norm at which
//! the uncertainty alone explains the residual, doubled until certified. A midpoint with
//! `mu_lower >= 1` is certified consistent (an explicit admissible `Delta_u`, disturbance
//! and the data satisfy (26)) and becomes `hi`; one with `mu_upper < 1` is certified
//! invalidated and becomes `lo`. Where the bounds straddle 1 the two ends are bisected
//! separately (upper-bound test below, lower-bound test above). It stops when
//! `hi - lo <= rel_tol * hi + abs_tol` (defaults `1e-7` relative, `0` absolute). The
//! result [`MinGamma::gamma`] is `hi` (a certified non-invalidating norm: conservative
//! for robust control), [`MinGamma::gamma_lower`] is `lo` (below it the model is
//! invalidated for certain). They differ by more than the tolerance only where the mu
//! bounds have a gap.
//!
//! **Additive closed form ([`min_gamma_additive`]).** With additive uncertainty and a
//! unitary `T_V`, `Delta_u W` covers the ball of radius `gamma |W|`, so the minimum is
//! `gamma = | (|T_V^H E_nom|_q - V~_q)_+ | / |W|`, for one output
//! `max(0, (|E| - V~) / |W|)`. The tests check the mu bisection against it.

use crate::cmat::{null_space, vnorm, CMat};
use crate::disturbance::DisturbanceModel;
use crate::mu::{bounds_impl, ln_d, Block, BlockStructure, MuBounds, MuConfig};
use crate::ValidationError;
use faer::Mat;
use frf_data::C64;

/// The uncertainty part `M11`, `M12`, `M21` of the interconnection `M^` and the structure
/// of `Delta_u` (which maps the `nq` outputs of `M11`/`M12` to its `np` inputs).
#[derive(Debug, Clone, PartialEq)]
pub struct UncertaintyModel {
    /// `M11` (`nq x np`).
    pub m11: Mat<C64>,
    /// `M12` (`nq x nu`).
    pub m12: Mat<C64>,
    /// `M21` (`ny x np`).
    pub m21: Mat<C64>,
    /// The structure of `Delta_u` (`np x nq`).
    pub structure: BlockStructure,
}

impl UncertaintyModel {
    /// Additive uncertainty `P^ + Delta_u`, `Delta_u` a full `ny x nu` block:
    /// `M11 = 0`, `M12 = I_nu`, `M21 = I_ny`.
    pub fn additive(ny: usize, nu: usize) -> Self {
        Self {
            m11: Mat::zeros(nu, ny),
            m12: identity(nu),
            m21: identity(ny),
            structure: BlockStructure::new(vec![Block::Full { rows: ny, cols: nu }]),
        }
    }

    /// Output multiplicative uncertainty `(I + Delta_u) P^`, `Delta_u` a full `ny x ny`
    /// block: `M11 = 0`, `M12 = P^`, `M21 = I_ny`.
    pub fn output_multiplicative(nominal: &Mat<C64>) -> Self {
        let ny = nominal.nrows();
        Self {
            m11: Mat::zeros(ny, ny),
            m12: nominal.clone(),
            m21: identity(ny),
            structure: BlockStructure::new(vec![Block::Full { rows: ny, cols: ny }]),
        }
    }
}

fn identity(n: usize) -> Mat<C64> {
    Mat::from_fn(n, n, |i, j| C64::new(if i == j { 1.0 } else { 0.0 }, 0.0))
}

/// The validation data of one line: input `W`, measured output `Z_m` and the nominal
/// model `M22 = P^`.
#[derive(Debug, Clone, PartialEq)]
pub struct LineData {
    /// `W` (`nu`).
    pub w: Vec<C64>,
    /// `Z_m` (`ny`).
    pub z_m: Vec<C64>,
    /// `P^` (`ny x nu`).
    pub nominal: Mat<C64>,
}

impl LineData {
    /// The nominal residual `E_nom = Z_m - P^ W` (10).
    pub fn residual(&self) -> Vec<C64> {
        let p = CMat::from_faer(&self.nominal);
        let pw = p.mul_vec(&self.w);
        self.z_m.iter().zip(&pw).map(|(a, b)| a - b).collect()
    }
}

/// Settings of the bisection.
#[derive(Debug, Clone, PartialEq)]
pub struct GammaConfig {
    /// Relative tolerance on `gamma` (default `1e-7`).
    pub rel_tol: f64,
    /// Absolute tolerance on `gamma` (default `0`).
    pub abs_tol: f64,
    /// Doublings of the initial upper end before giving up (default 60).
    pub max_doublings: usize,
    /// The mu bounds' settings.
    pub mu: MuConfig,
}

impl Default for GammaConfig {
    fn default() -> Self {
        Self {
            rel_tol: 1e-7,
            abs_tol: 0.0,
            max_doublings: 60,
            mu: MuConfig::default(),
        }
    }
}

/// The result of the FDMVOP at one line.
#[derive(Debug, Clone, PartialEq)]
pub struct MinGamma {
    /// Certified non-invalidating norm (bisection's upper end).
    pub gamma: f64,
    /// Certified invalidating below (bisection's lower end).
    pub gamma_lower: f64,
    /// The part of `E_nom` the uncertainty explains at `gamma`,
    /// `E_nom - T_V Delta_v V~ 1` of the certificate (`ny`).
    pub explained_by_uncertainty: Vec<C64>,
    /// Number of mu evaluations.
    pub evaluations: usize,
}

/// The implicit LFT of Proposition 12 at norm `gamma`: `(M, N, structure)` and the parts
/// needed to read a certificate.
pub(crate) struct ImplicitLft {
    m: CMat,
    q: CMat,
    structure: BlockStructure,
    e_nom: Vec<C64>,
    mbar21: CMat,
    ny: usize,
}

fn check_problem(
    unc: &UncertaintyModel,
    line: &LineData,
    dist: &DisturbanceModel,
) -> Result<(), ValidationError> {
    let (ny, nu) = (line.nominal.nrows(), line.nominal.ncols());
    let dims = |what: &str, e: String, g: String| Err(ValidationError::dimension(what, e, g));
    if line.w.len() != nu {
        return dims(
            "W vs nominal model",
            format!("{nu}"),
            format!("{}", line.w.len()),
        );
    }
    if line.z_m.len() != ny {
        return dims(
            "Z_m vs nominal model",
            format!("{ny}"),
            format!("{}", line.z_m.len()),
        );
    }
    if dist.ny() != ny || dist.t_v.nrows() != ny || dist.t_v.ncols() != ny {
        return dims(
            "disturbance model vs nominal model",
            format!("{ny} outputs"),
            format!(
                "{} radii, T_V {} x {}",
                dist.ny(),
                dist.t_v.nrows(),
                dist.t_v.ncols()
            ),
        );
    }
    let (np, nq) = (unc.structure.n_rows(), unc.structure.n_cols());
    if unc.m11.nrows() != nq || unc.m11.ncols() != np {
        return dims(
            "M11",
            format!("{nq} x {np}"),
            format!("{} x {}", unc.m11.nrows(), unc.m11.ncols()),
        );
    }
    if unc.m12.nrows() != nq || unc.m12.ncols() != nu {
        return dims(
            "M12",
            format!("{nq} x {nu}"),
            format!("{} x {}", unc.m12.nrows(), unc.m12.ncols()),
        );
    }
    if unc.m21.nrows() != ny || unc.m21.ncols() != np {
        return dims(
            "M21",
            format!("{ny} x {np}"),
            format!("{} x {}", unc.m21.nrows(), unc.m21.ncols()),
        );
    }
    let finite = |v: &[C64]| v.iter().all(|z| z.re.is_finite() && z.im.is_finite());
    if !finite(&line.w) || !finite(&line.z_m) || !CMat::from_faer(&line.nominal).is_finite() {
        return Err(ValidationError::invalid_input(
            "validation line",
            "W, Z_m or the nominal model has a non-finite entry",
        ));
    }
    if dist.v_tilde.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(ValidationError::invalid_input(
            "disturbance model",
            "a radius is negative or not finite",
        ));
    }
    Ok(())
}

/// Builds the implicit LFT (28) at `gamma` and reduces it by Proposition 12.
fn implicit_lft(
    unc: &UncertaintyModel,
    line: &LineData,
    dist: &DisturbanceModel,
    gamma: f64,
) -> ImplicitLft {
    let ny = line.z_m.len();
    let (np, nq) = (unc.structure.n_rows(), unc.structure.n_cols());
    let e_nom = line.residual();
    let m11 = CMat::from_faer(&unc.m11);
    let m12w = CMat::from_faer(&unc.m12).mul_vec(&line.w);
    let m21 = CMat::from_faer(&unc.m21);
    // x = [x_v (ny); x_u (np)], y = [y_v (ny); y_u (nq)]
    let nx = ny + np;
    let nyy = ny + nq;
    let mbar11 = CMat::from_fn(nyy, nx, |i, j| {
        if i >= ny && j >= ny {
            m11[(i - ny, j - ny)] * gamma
        } else {
            C64::new(0.0, 0.0)
        }
    });
    let mbar12: Vec<C64> = (0..nyy)
        .map(|i| {
            if i < ny {
                C64::new(dist.v_tilde[i], 0.0)
            } else {
                -m12w[i - ny]
            }
        })
        .collect();
    let mbar21 = CMat::from_fn(ny, nx, |i, j| {
        if j < ny {
            -dist.t_v[(i, j)]
        } else {
            m21[(i, j - ny)] * gamma
        }
    });
    let e2: f64 = e_nom.iter().map(|z| z.norm_sqr()).sum();
    // X22 M_bar21 (a row, 1 x nx): E^H M_bar21 / |E|^2
    let xm: Vec<C64> = mbar21
        .adjoint_mul_vec(&e_nom)
        .iter()
        .map(|z| z.conj() / e2)
        .collect();
    let m = CMat::from_fn(nyy, nx, |i, j| mbar11[(i, j)] - mbar12[i] * xm[j]);
    let n = CMat::from_fn(ny, nx, |i, j| mbar21[(i, j)] - e_nom[i] * xm[j]);
    let scale = mbar21.norm_fro().max(f64::MIN_POSITIVE);
    let q = null_space(&n, 1e-10 * scale);
    let mut blocks = vec![Block::Scalar; ny];
    blocks.extend(unc.structure.blocks.iter().copied());
    ImplicitLft {
        m,
        q,
        structure: BlockStructure::new(blocks),
        e_nom,
        mbar21,
        ny,
    }
}

impl ImplicitLft {
    fn bounds(&self, cfg: &MuConfig, t0: Option<&[f64]>) -> MuBounds {
        bounds_impl(&self.m, self.q.clone(), true, &self.structure, cfg, t0)
    }

    /// `E_nom - T_V x_v / alpha` for the certificate `x` (`alpha = -X22 M_bar21 x`): the
    /// part of the residual the uncertainty explains.
    fn explained(&self, x: &[C64]) -> Vec<C64> {
        let e2: f64 = self.e_nom.iter().map(|z| z.norm_sqr()).sum();
        let mx = self.mbar21.mul_vec(x);
        let alpha: C64 = -self
            .e_nom
            .iter()
            .zip(&mx)
            .map(|(e, v)| e.conj() * v)
            .sum::<C64>()
            / e2;
        if alpha.norm() == 0.0 {
            return self.e_nom.clone();
        }
        // 0 = M_bar21 x + E alpha, M_bar21 x = -T_V x_v + gamma M21 x_u:
        // disturbance part T_V x_v / alpha; the rest is the uncertainty's
        let mut tv_xv = vec![C64::new(0.0, 0.0); self.ny];
        for (i, t) in tv_xv.iter_mut().enumerate() {
            for j in 0..self.ny {
                *t += -self.mbar21[(i, j)] * x[j];
            }
        }
        self.e_nom
            .iter()
            .zip(&tv_xv)
            .map(|(e, d)| e - d / alpha)
            .collect()
    }
}

/// The mu bounds of the FDMVDP at norm `gamma` (Proposition 12): the model is not
/// invalidated iff mu >= 1; `lower >= 1` certifies it, `upper < 1` refutes it.
pub fn invalidation_mu(
    unc: &UncertaintyModel,
    line: &LineData,
    dist: &DisturbanceModel,
    gamma: f64,
    cfg: &MuConfig,
) -> Result<MuBounds, ValidationError> {
    check_problem(unc, line, dist)?;
    if !(gamma.is_finite() && gamma >= 0.0) {
        return Err(ValidationError::config("gamma", gamma, "finite and >= 0"));
    }
    if vnorm(&line.residual()) == 0.0 {
        return Err(ValidationError::invalid_input(
            "validation line",
            "the nominal residual is zero (Assumption 5): nothing to validate",
        ));
    }
    Ok(implicit_lft(unc, line, dist, gamma).bounds(cfg, None))
}

/// The FDMVOP at one line by bisection on `gamma` (see the module documentation).
pub fn min_gamma(
    unc: &UncertaintyModel,
    line: &LineData,
    dist: &DisturbanceModel,
    cfg: &GammaConfig,
) -> Result<MinGamma, ValidationError> {
    check_problem(unc, line, dist)?;
    let e_nom = line.residual();
    let en = vnorm(&e_nom);
    if en == 0.0 {
        return Ok(MinGamma {
            gamma: 0.0,
            gamma_lower: 0.0,
            explained_by_uncertainty: e_nom,
            evaluations: 0,
        });
    }
    let mut evals = 0;
    let mut t: Option<Vec<f64>> = None;
    let mut eval = |g: f64, t: &mut Option<Vec<f64>>| -> (MuBounds, ImplicitLft) {
        evals += 1;
        let lft = implicit_lft(unc, line, dist, g);
        let b = lft.bounds(&cfg.mu, t.as_deref());
        *t = Some(ln_d(&b));
        (b, lft)
    };
    let (b0, lft0) = eval(0.0, &mut t);
    if b0.lower >= 1.0 {
        let ex = lft0.explained(&b0.x);
        return Ok(MinGamma {
            gamma: 0.0,
            gamma_lower: 0.0,
            explained_by_uncertainty: ex,
            evaluations: evals,
        });
    }
    let mut lo = 0.0;
    // initial upper end: the uncertainty alone explains E_nom when gamma |M21| |M12 W|
    // reaches |E_nom| (additive: |E| / |W|)
    let gain =
        CMat::from_faer(&unc.m21).sigma_max() * vnorm(&CMat::from_faer(&unc.m12).mul_vec(&line.w));
    let mut hi = if gain > 0.0 { en / gain } else { 1.0 };
    let mut hi_cert = None;
    for _ in 0..=cfg.max_doublings {
        let (b, lft) = eval(hi, &mut t);
        if b.lower >= 1.0 {
            hi_cert = Some(lft.explained(&b.x));
            break;
        }
        if b.upper < 1.0 {
            lo = hi;
        }
        hi *= 2.0;
    }
    let Some(mut cert) = hi_cert else {
        return Err(ValidationError::invalid_input(
            "uncertainty model",
            format!(
                "no uncertainty norm up to {hi:.3e} explains the residual: the structure \
                 cannot reach the residual's direction (Assumption 4)"
            ),
        ));
    };
    let done = |lo: f64, hi: f64| hi - lo <= cfg.rel_tol * hi + cfg.abs_tol;
    // joint bisection while the bounds decide
    let mut split = None;
    while !done(lo, hi) {
        let c = 0.5 * (lo + hi);
        let (b, lft) = eval(c, &mut t);
        if b.lower >= 1.0 {
            hi = c;
            cert = lft.explained(&b.x);
        } else if b.upper < 1.0 {
            lo = c;
        } else {
            split = Some(c);
            break;
        }
    }
    if let Some(c) = split {
        // upper end in [c, hi] by the lower bound
        let mut a = c;
        while !done(a, hi) {
            let m = 0.5 * (a + hi);
            let (b, lft) = eval(m, &mut t);
            if b.lower >= 1.0 {
                hi = m;
                cert = lft.explained(&b.x);
            } else {
                a = m;
            }
        }
        // lower end in [lo, c] by the upper bound
        let mut z = c;
        while !done(lo, z) {
            let m = 0.5 * (lo + z);
            let (b, _) = eval(m, &mut t);
            if b.upper < 1.0 {
                lo = m;
            } else {
                z = m;
            }
        }
    }
    Ok(MinGamma {
        gamma: hi,
        gamma_lower: lo,
        explained_by_uncertainty: cert,
        evaluations: evals,
    })
}

/// The exact FDMVOP for additive uncertainty and a unitary `T_V` (see the module
/// documentation): `gamma = |(|T_V^H E_nom|_q - V~_q)_+| / |W|`, with the part of `E_nom`
/// the uncertainty explains. Errors when `T_V` is not unitary (to `1e-8`) or `W = 0`.
pub fn min_gamma_additive(
    line: &LineData,
    dist: &DisturbanceModel,
) -> Result<(f64, Vec<C64>), ValidationError> {
    let (ny, nu) = (line.nominal.nrows(), line.nominal.ncols());
    check_problem(&UncertaintyModel::additive(ny, nu), line, dist)?;
    let t = CMat::from_faer(&dist.t_v);
    let tt = t.gram();
    for i in 0..ny {
        for j in 0..ny {
            let e = if i == j { 1.0 } else { 0.0 };
            if (tt[(i, j)] - C64::new(e, 0.0)).norm() > 1e-8 {
                return Err(ValidationError::invalid_input(
                    "disturbance model",
                    "T_V is not unitary: the additive closed form does not apply (use min_gamma)",
                ));
            }
        }
    }
    let wn = vnorm(&line.w);
    if wn == 0.0 {
        return Err(ValidationError::invalid_input(
            "validation line",
            "the input W is zero at this line (not in Omega_val, eq. (7))",
        ));
    }
    let e = line.residual();
    let c = t.adjoint_mul_vec(&e);
    let shrunk: Vec<C64> = c
        .iter()
        .zip(&dist.v_tilde)
        .map(|(z, v)| {
            let a = z.norm();
            if a > *v {
                z * ((a - v) / a)
            } else {
                C64::new(0.0, 0.0)
            }
        })
        .collect();
    let r = t.mul_vec(&shrunk);
    Ok((vnorm(&shrunk) / wn, r))
}
