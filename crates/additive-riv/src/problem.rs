//! The fitting problem shared by the initialisation and the iterations: the data in the
//! band, the weights, and the layout of the parameters as the solver sees them.
//!
//! Parameters are split as the structure of the additive model suggests (section 3.2 of
//! the wafer-stage paper): the numerator coefficients enter each entry `e` of `vec(G)`
//! separately (the identity blocks of (12), (14) and (25)), while the denominator
//! coefficients (and a fitted delay) are shared by all entries. `eta[e * n_num + j]` is
//! numerator coefficient `j` (submodel by submodel, power by power) of entry `e`;
//! `shared` holds the scaled denominator coefficients, submodel by submodel, then the
//! delay when it is fitted.

use crate::{AdditiveModel, RivError};
use frf_data::{FrfDataset, Weighting, C64};

/// The data of one fit: frequencies, values and weights in the estimator's layout.
#[derive(Debug, Clone)]
pub struct FitData {
    /// Number of lines.
    pub n: usize,
    /// Outputs.
    pub ny: usize,
    /// Inputs.
    pub nu: usize,
    /// Angular frequencies, rad/s.
    pub omega: Vec<f64>,
    /// `G[k * m + e]`, `m = ny * nu`.
    pub g: Vec<C64>,
    /// Weights `w[k * m + e]` of the criterion `sum w |E|^2`.
    pub w: Vec<f64>,
    /// Frequency band, Hz.
    pub band_hz: (f64, f64),
}

impl FitData {
    /// Collects `data` and its weights; fails on non-finite values, a 0 Hz line or an
    /// all-zero weighting.
    pub fn new<D: FrfDataset + ?Sized>(data: &D, weighting: &Weighting) -> Result<Self, RivError> {
        let n = data.n_lines();
        let (ny, nu) = (data.ny(), data.nu());
        if n == 0 {
            return Err(RivError::invalid("data", "0 lines", "nothing to fit"));
        }
        let g = data.values_vec();
        if let Some(idx) = g
            .iter()
            .position(|z| !(z.re.is_finite() && z.im.is_finite()))
        {
            let m = ny * nu;
            return Err(RivError::Data(frf_data::FrfError::InvalidData {
                why: format!(
                    "non-finite value at line {} ({} Hz), entry G{}_{}",
                    idx / m,
                    data.freq_hz(idx / m),
                    idx % m % ny + 1,
                    idx % m / ny + 1
                ),
            }));
        }
        let omega = data.omegas();
        if omega[0] <= 0.0 {
            return Err(RivError::invalid(
                "band",
                format!("{} Hz", data.freq_hz(0)),
                "the 0 Hz line cannot be fitted (integrators are infinite there); start the band above 0",
            ));
        }
        let w = weighting.weights(data)?;
        Ok(Self {
            n,
            ny,
            nu,
            band_hz: (data.freq_hz(0), data.freq_hz(n - 1)),
            omega,
            g,
            w,
        })
    }

    /// Number of entries `ny * nu`.
    pub fn m(&self) -> usize {
        self.ny * self.nu
    }

    /// Number of real observations with a positive weight.
    pub fn observations(&self) -> usize {
        2 * self.w.iter().filter(|&&x| x > 0.0).count()
    }
}

/// Where each submodel's parameters sit in the solver's vectors.
#[derive(Debug, Clone)]
pub struct Layout {
    /// Per submodel: offset of its first numerator coefficient within an entry's block.
    pub num_offset: Vec<usize>,
    /// Per submodel: offset of its first denominator coefficient within `shared`.
    pub den_offset: Vec<usize>,
    /// Numerator coefficients per entry.
    pub n_num: usize,
    /// Denominator coefficients (all submodels).
    pub n_den: usize,
    /// Whether the delay is the last shared parameter.
    pub fit_delay: bool,
}

impl Layout {
    /// The layout of `model`.
    pub fn of(model: &AdditiveModel) -> Self {
        let mut num_offset = Vec::new();
        let mut den_offset = Vec::new();
        let (mut nn, mut nd) = (0, 0);
        for s in &model.submodels {
            num_offset.push(nn);
            den_offset.push(nd);
            nn += s.num.len();
            nd += s.den.len();
        }
        Self {
            num_offset,
            den_offset,
            n_num: nn,
            n_den: nd,
            fit_delay: model.factor.fit_delay,
        }
    }
    /// Shared parameters: denominators plus the delay when fitted.
    pub fn n_shared(&self) -> usize {
        self.n_den + usize::from(self.fit_delay)
    }
    /// Total parameters for `m` entries.
    pub fn n_total(&self, m: usize) -> usize {
        self.n_shared() + self.n_num * m
    }
}

/// Reads the solver vectors out of a model.
pub fn pack(model: &AdditiveModel, lay: &Layout) -> (Vec<f64>, Vec<f64>) {
    let (ny, nu) = (
        frf_data::ModelStructure::ny(model),
        frf_data::ModelStructure::nu(model),
    );
    let m = ny * nu;
    let mut shared = Vec::with_capacity(lay.n_shared());
    for s in &model.submodels {
        shared.extend_from_slice(&s.den);
    }
    if lay.fit_delay {
        shared.push(model.factor.delay_s);
    }
    let mut eta = vec![0.0; m * lay.n_num];
    for (i, s) in model.submodels.iter().enumerate() {
        for (t, b) in s.num.iter().enumerate() {
            let j = lay.num_offset[i] + t;
            for col in 0..nu {
                for row in 0..ny {
                    eta[(col * ny + row) * lay.n_num + j] = b[(row, col)];
                }
            }
        }
    }
    (shared, eta)
}

/// Writes the solver vectors into a model.
pub fn unpack(model: &mut AdditiveModel, lay: &Layout, shared: &[f64], eta: &[f64]) {
    let (ny, nu) = (
        frf_data::ModelStructure::ny(model),
        frf_data::ModelStructure::nu(model),
    );
    for (i, s) in model.submodels.iter_mut().enumerate() {
        let d0 = lay.den_offset[i];
        let nd = s.den.len();
        s.den.copy_from_slice(&shared[d0..d0 + nd]);
        for (t, b) in s.num.iter_mut().enumerate() {
            let j = lay.num_offset[i] + t;
            for col in 0..nu {
                for row in 0..ny {
                    b[(row, col)] = eta[(col * ny + row) * lay.n_num + j];
                }
            }
        }
    }
    if lay.fit_delay {
        model.factor.delay_s = shared[lay.n_den];
    }
}

/// Per-line quantities of the current denominators: the numerator basis
/// `u_j(k) = x^r / (pi(x) A(x))` (the regressor (25)), the denominator factors
/// `-x^r / A(x)` whose product with a submodel's response is the gradient column (12),
/// and the known factor.
pub struct Basis {
    /// `u[k * n_num + j]`.
    pub u: Vec<C64>,
    /// `dcol[k * n_den + d]`: `-x^r / A_i(x)` for denominator coefficient `d` (of
    /// submodel `i`, power `r`).
    pub dcol: Vec<C64>,
    /// Known factor `F_k`.
    pub f: Vec<C64>,
    /// `|F_k|`.
    pub f_abs: Vec<f64>,
    /// `1 / F_k`.
    pub f_inv: Vec<C64>,
}

impl Basis {
    /// Evaluates the basis of `model` at `omega`.
    pub fn new(model: &AdditiveModel, lay: &Layout, omega: &[f64]) -> Self {
        let n = omega.len();
        let mut u = Vec::with_capacity(n * lay.n_num);
        let mut dcol = Vec::with_capacity(n * lay.n_den);
        let mut f = Vec::with_capacity(n);
        for &w in omega {
            for s in &model.submodels {
                let x = model.variable(s, w);
                let a = s.den_at(x);
                let pa = (model.integrator_factor(s.integrators, x) * a).inv();
                let mut xr = x.powi(s.num_start as i32);
                for _ in 0..s.num.len() {
                    u.push(xr * pa);
                    xr *= x;
                }
                let ia = a.inv();
                let mut xr = x;
                for _ in 0..s.den.len() {
                    dcol.push(-xr * ia);
                    xr *= x;
                }
            }
            f.push(model.factor.at(w));
        }
        let f_abs = f.iter().map(|z| z.norm()).collect();
        let f_inv = f.iter().map(|z| z.inv()).collect();
        Self {
            u,
            dcol,
            f,
            f_abs,
            f_inv,
        }
    }
}

/// Weighted cost `sum_k sum_e w |G - F P|^2` of `eta` given the basis, and optionally
/// the residual `E = G - F P` (in the data's layout).
pub fn cost(
    data: &FitData,
    lay: &Layout,
    basis: &Basis,
    eta: &[f64],
    resid: Option<&mut Vec<C64>>,
) -> f64 {
    let m = data.m();
    let nn = lay.n_num;
    let mut total = 0.0;
    let mut out = resid;
    if let Some(r) = out.as_deref_mut() {
        r.clear();
        r.resize(data.n * m, C64::new(0.0, 0.0));
    }
    for k in 0..data.n {
        let uk = &basis.u[k * nn..(k + 1) * nn];
        let fk = basis.f[k];
        for e in 0..m {
            let be = &eta[e * nn..(e + 1) * nn];
            let mut p = C64::new(0.0, 0.0);
            for j in 0..nn {
                p += uk[j] * be[j];
            }
            let err = data.g[k * m + e] - fk * p;
            total += data.w[k * m + e] * err.norm_sqr();
            if let Some(r) = out.as_deref_mut() {
                r[k * m + e] = err;
            }
        }
    }
    total
}
