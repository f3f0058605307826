//! The fitting problem shared by the initialisation and the iterations: the data in the
//! band, the weights, and the layout of the parameters as the solver sees them.
//!
//! Parameters are split as the structure of the additive model suggests (section 3.2 of
//! the wafer-stage paper): the numerator coefficients enter each entry `e` of `vec(G)`
//! separately (the identity blocks of (12), (14) and (25)), while the denominator
//! coefficients (and a fitted delay) are shared by all entries. `eta[e * n_num + j]` is
//! numerator coefficient `j` (submodel by submodel, power by power) of entry `e`;
//! `shared` holds the scaled denominator coefficients, submodel by submodel, then the
//! delay when it is fitted, then per dynamics factor its denominator and numerator
//! coefficients (`a~_1 .. a~_n`, `b~_1 .. b~_m` of `B(x) / A(x)`).

use crate::{AdditiveModel, RivError};
use frf_data::{FrfDataset, Weighting, C64};
use rayon::prelude::*;

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
    /// Entry-major copies for the per-entry loops: `Re G[e * n + k]`.
    pub g_re: Vec<f64>,
    /// `Im G[e * n + k]`.
    pub g_im: Vec<f64>,
    /// `sqrt(w)[e * n + k]`.
    pub sqrt_w: Vec<f64>,
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
        Ok(Self::from_parts(
            omega,
            ny,
            nu,
            g,
            w,
            (data.freq_hz(0), data.freq_hz(n - 1)),
        ))
    }

    /// Builds the problem from line-major values and weights (`[k * m + e]`).
    pub fn from_parts(
        omega: Vec<f64>,
        ny: usize,
        nu: usize,
        g: Vec<C64>,
        w: Vec<f64>,
        band_hz: (f64, f64),
    ) -> Self {
        let n = omega.len();
        let m = ny * nu;
        let mut g_re = vec![0.0; n * m];
        let mut g_im = vec![0.0; n * m];
        let mut sqrt_w = vec![0.0; n * m];
        for k in 0..n {
            for e in 0..m {
                g_re[e * n + k] = g[k * m + e].re;
                g_im[e * n + k] = g[k * m + e].im;
                sqrt_w[e * n + k] = w[k * m + e].sqrt();
            }
        }
        Self {
            n,
            ny,
            nu,
            omega,
            g,
            w,
            band_hz,
            g_re,
            g_im,
            sqrt_w,
        }
    }

    /// Number of entries `ny * nu`.
    pub fn m(&self) -> usize {
        self.ny * self.nu
    }

    /// The weighted energy of the data, `sum w |G|^2`: the cost of the zero model.
    pub fn weighted_energy(&self) -> f64 {
        self.w
            .iter()
            .zip(&self.g)
            .map(|(w, g)| w * g.norm_sqr())
            .sum()
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
    /// Whether the delay follows the denominators among the shared parameters.
    pub fit_delay: bool,
    /// Coefficients of the dynamics factors, denominator then numerator of each (last
    /// among the shared parameters).
    pub n_factor: usize,
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
            n_factor: model
                .dynamics
                .iter()
                .map(|d| d.den.len() + d.num.len())
                .sum(),
        }
    }
    /// Shared parameters: denominators, the delay when fitted, the dynamics factors.
    pub fn n_shared(&self) -> usize {
        self.n_den + usize::from(self.fit_delay) + self.n_factor
    }
    /// Index of the first factor parameter (delay, then dynamics) among the shared ones.
    pub fn factor_offset(&self) -> usize {
        self.n_den
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
    for d in &model.dynamics {
        shared.extend_from_slice(&d.den);
        shared.extend_from_slice(&d.num);
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
    unpack_raw(model, lay, shared, eta);
    model.sync_shapes();
}

fn unpack_raw(model: &mut AdditiveModel, lay: &Layout, shared: &[f64], eta: &[f64]) {
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
    let mut off = lay.n_den;
    if lay.fit_delay {
        model.factor.delay_s = shared[off];
        off += 1;
    }
    for d in &mut model.dynamics {
        let n = d.den.len();
        d.den.copy_from_slice(&shared[off..off + n]);
        off += n;
        let n = d.num.len();
        d.num.copy_from_slice(&shared[off..off + n]);
        off += n;
    }
}

/// Per-line quantities of the current denominators, stored column by column (one
/// contiguous run of lines per column, real and imaginary parts apart) so that the
/// per-entry loops run over lines and vectorise:
///
/// - the numerator basis `u_j(k) = x^r / (pi(x) A(x))` (the regressor (25));
/// - the denominator factors `d_d(k) = -x^r / A(x)`, whose product with a submodel's
///   response is its gradient column (12);
/// - the known factor `F_k`, its modulus and inverse.
pub struct Basis {
    /// Number of lines.
    pub n: usize,
    /// `Re u_j(k)` at `[j * n + k]`.
    pub u_re: Vec<f64>,
    /// `Im u_j(k)` at `[j * n + k]`.
    pub u_im: Vec<f64>,
    /// `Re d_d(k)` at `[d * n + k]`.
    pub d_re: Vec<f64>,
    /// `Im d_d(k)` at `[d * n + k]`.
    pub d_im: Vec<f64>,
    /// The factor of each entry `F_ke` (known factor times dynamics factors) at
    /// `[f_offset(e) + k]`: one row per entry with dynamics factors, else one row that
    /// every entry shares (the known factor is the same for all).
    pub f: Vec<C64>,
    /// `|F_ke|`.
    pub f_abs: Vec<f64>,
    /// `1 / F_ke`.
    pub f_inv: Vec<C64>,
    /// For each fitted factor parameter `q` (delay, then the dynamics coefficients,
    /// denominator then numerator of each factor): `d ln F / d theta_q` at `[q * n + k]`
    /// (the same for every entry it affects).
    pub dlnf: Vec<C64>,
    /// Whether factor parameter `q` affects entry `e`: `[q * m + e]`.
    pub dlnf_mask: Vec<bool>,
    /// Submodels that bypass the known factor (their response depends on the delay too).
    pub bypass: Vec<bool>,
    /// `(d, j)`: denominator coefficient `d` and numerator coefficient `j` of the same
    /// submodel; `du[p]` is `d u_j / d a_d` for pair `p`.
    pub pairs: Vec<(usize, usize)>,
    /// Pairs of each denominator coefficient: `pairs[pair_range[d].clone()]`.
    pub pair_range: Vec<std::ops::Range<usize>>,
    /// `Re d u_j / d a_d` at `[p * n + k]`.
    pub du_re: Vec<f64>,
    /// `Im d u_j / d a_d` at `[p * n + k]`.
    pub du_im: Vec<f64>,
}

impl Basis {
    /// The numerator regressor columns `u_j(k) s_k` of the first `nn` basis functions
    /// with the line scales `s` (real parts in rows `0..n`, imaginary parts in rows
    /// `n..2n`), as the first `nn` columns of a `2n x (nn + extra)` matrix whose `extra`
    /// last columns are left zero (for right-hand sides).
    pub fn scaled_columns(&self, s: &[f64], nn: usize, extra: usize) -> faer::Mat<f64> {
        let n = self.n;
        let mut ut = faer::Mat::<f64>::zeros(2 * n, nn + extra);
        for j in 0..nn {
            let col = ut.col_as_slice_mut(j);
            let (cr, ci) = col.split_at_mut(n);
            for k in 0..n {
                cr[k] = self.u_re[j * n + k] * s[k];
                ci[k] = self.u_im[j * n + k] * s[k];
            }
        }
        ut
    }

    /// Evaluates the basis of `model` at `omega`.
    pub fn new(model: &AdditiveModel, lay: &Layout, omega: &[f64]) -> Self {
        let n = omega.len();
        let ny = frf_data::ModelStructure::ny(model);
        let nu = frf_data::ModelStructure::nu(model);
        let m = ny * nu;
        let mut u_re = vec![0.0; n * lay.n_num];
        let mut u_im = vec![0.0; n * lay.n_num];
        let mut d_re = vec![0.0; n * lay.n_den];
        let mut d_im = vec![0.0; n * lay.n_den];
        // without dynamics factors every entry has the known factor: one shared row
        let f_rows = if model.dynamics.is_empty() { 1 } else { m };
        let mut f = vec![C64::new(0.0, 0.0); n * f_rows];
        let n_fp = usize::from(lay.fit_delay) + lay.n_factor;
        let mut dlnf = vec![C64::new(0.0, 0.0); n * n_fp];
        let mut dlnf_mask = vec![false; n_fp * m];
        // pairs (d, j) per submodel
        let mut pairs = Vec::new();
        let mut pair_range = Vec::with_capacity(lay.n_den);
        for (i, s) in model.submodels.iter().enumerate() {
            for r in 0..s.den.len() {
                let start = pairs.len();
                for t in 0..s.num.len() {
                    pairs.push((lay.den_offset[i] + r, lay.num_offset[i] + t));
                }
                pair_range.push(start..pairs.len());
            }
        }
        let mut du_re = vec![0.0; n * pairs.len()];
        let mut du_im = vec![0.0; n * pairs.len()];
        // exact-hold modes: derivative of the pole-dependent numerator shape by central
        // differences of (beta_1, beta_2) with respect to (a_1, a_2)
        let ts = match model.domain() {
            crate::Domain::ZohDiscrete { ts } => ts,
            crate::Domain::Continuous => 1.0,
        };
        let dshape: Vec<Option<[[f64; 2]; 2]>> = model
            .submodels
            .iter()
            .map(|s| {
                if !s.zoh_shape {
                    return None;
                }
                let mut out = [[0.0; 2]; 2];
                for r in 0..2 {
                    let h = 1e-6 * s.den[r].abs().max(1e-6);
                    let mut up = s.den.clone();
                    let mut dn = s.den.clone();
                    up[r] += h;
                    dn[r] -= h;
                    let (bu, bd) = (
                        crate::model::zoh_mode_shape(&up, ts)?,
                        crate::model::zoh_mode_shape(&dn, ts)?,
                    );
                    out[r] = [(bu[0] - bd[0]) / (2.0 * h), (bu[1] - bd[1]) / (2.0 * h)];
                }
                Some(out)
            })
            .collect();
        // per line: the known factor and (with the exact hold) the discrete variable,
        // the same for every submodel (one sincos per line)
        let f0: Vec<C64> = omega.iter().map(|&w| model.factor.at(w)).collect();
        let f0_inv: Vec<C64> = f0.iter().map(|v| v.inv()).collect();
        let z: Option<Vec<C64>> = match model.domain() {
            crate::Domain::ZohDiscrete { ts } => Some(
                omega
                    .iter()
                    .map(|&w| C64::from_polar(1.0, -w * ts))
                    .collect(),
            ),
            crate::Domain::Continuous => None,
        };
        // each submodel fills its own consecutive columns of u, d and du
        let mut cols: Vec<SubmodelColumns<'_>> = Vec::with_capacity(model.submodels.len());
        {
            let (mut ur, mut ui) = (&mut u_re[..], &mut u_im[..]);
            let (mut dr, mut di) = (&mut d_re[..], &mut d_im[..]);
            let (mut pr, mut pi) = (&mut du_re[..], &mut du_im[..]);
            for s in &model.submodels {
                let (nu_s, nd_s) = (s.num.len() * n, s.den.len() * n);
                let np_s = s.num.len() * s.den.len() * n;
                cols.push(SubmodelColumns {
                    u_re: take_front(&mut ur, nu_s),
                    u_im: take_front(&mut ui, nu_s),
                    d_re: take_front(&mut dr, nd_s),
                    d_im: take_front(&mut di, nd_s),
                    du_re: take_front(&mut pr, np_s),
                    du_im: take_front(&mut pi, np_s),
                });
            }
        }
        let fill = |(i, c): (usize, SubmodelColumns<'_>)| {
            fill_submodel(
                model,
                i,
                omega,
                z.as_deref(),
                &f0_inv,
                dshape[i].as_ref(),
                c,
            )
        };
        if n * model.submodels.len() >= PARALLEL_BASIS_WORK && model.submodels.len() > 1 {
            cols.into_par_iter().enumerate().for_each(fill);
        } else {
            cols.into_iter().enumerate().for_each(fill);
        }
        for (k, &w) in omega.iter().enumerate() {
            let f0 = f0[k];
            for e in 0..f_rows {
                f[e * n + k] = f0;
            }
            let mut q = 0;
            if lay.fit_delay {
                // ln F = -j w tau + ...
                dlnf[q * n + k] = C64::new(0.0, -w);
                q += 1;
            }
            for dynf in &model.dynamics {
                let a = dynf.den_at(w);
                let ia = a.inv();
                let b = dynf.num_at(w);
                let h = b * ia;
                for j in 0..nu {
                    for i in 0..ny {
                        if dynf.affects(i, j) {
                            f[(j * ny + i) * n + k] *= h;
                        }
                    }
                }
                // ln F = ln B(x) - ln A(x) + ...: d/d a~_r = -x^r / A(x),
                // d/d b~_r = x^r / B(x)
                let x = C64::new(0.0, w / dynf.scale);
                let mut xr = x;
                for _ in 0..dynf.den.len() {
                    dlnf[q * n + k] = -xr * ia;
                    xr *= x;
                    q += 1;
                }
                if !dynf.num.is_empty() {
                    let ib = b.inv();
                    let mut xr = x;
                    for _ in 0..dynf.num.len() {
                        dlnf[q * n + k] = xr * ib;
                        xr *= x;
                        q += 1;
                    }
                }
            }
        }
        let mut q = 0;
        if lay.fit_delay {
            dlnf_mask[..m].fill(true);
            q += 1;
        }
        for dynf in &model.dynamics {
            for _ in 0..dynf.den.len() + dynf.num.len() {
                for j in 0..nu {
                    for i in 0..ny {
                        dlnf_mask[q * m + j * ny + i] = dynf.affects(i, j);
                    }
                }
                q += 1;
            }
        }
        // |F| without hypot's overflow guard: F is a delay, a hold, (j w)^k and
        // first/second-order factors, far from the range where squares overflow
        let f_abs = f
            .iter()
            .map(|z| (z.re * z.re + z.im * z.im).sqrt())
            .collect();
        let f_inv = f.iter().map(|z| z.inv()).collect();
        Self {
            n,
            u_re,
            u_im,
            d_re,
            d_im,
            f,
            f_abs,
            f_inv,
            dlnf,
            dlnf_mask,
            pairs,
            pair_range,
            du_re,
            du_im,
            bypass: model.submodels.iter().map(|s| s.bypass_factor).collect(),
        }
    }

    /// Offset of entry `e`'s row in [`Self::f`], [`Self::f_abs`] and [`Self::f_inv`].
    #[inline]
    pub fn f_offset(&self, e: usize) -> usize {
        if self.f.len() > self.n {
            e * self.n
        } else {
            0
        }
    }

    /// `u_j(k)` as a complex number.
    #[inline]
    pub fn u(&self, j: usize, k: usize) -> C64 {
        C64::new(self.u_re[j * self.n + k], self.u_im[j * self.n + k])
    }
}

/// Line-submodels (`lines x submodels`) from which [`Basis::new`] fills the submodels'
/// columns on the rayon pool: the wafer stage (3960 lines, 19 submodels, 7.5e4) is
/// above it, a SISO fit of a few hundred lines and modes below.
const PARALLEL_BASIS_WORK: usize = 20_000;

/// The first `len` values of `rest`, which keeps the others.
fn take_front<'a>(rest: &mut &'a mut [f64], len: usize) -> &'a mut [f64] {
    let (front, back) = std::mem::take(rest).split_at_mut(len);
    *rest = back;
    front
}

/// One submodel's columns of a [`Basis`] (`[t * n + k]` within each slice).
struct SubmodelColumns<'a> {
    u_re: &'a mut [f64],
    u_im: &'a mut [f64],
    d_re: &'a mut [f64],
    d_im: &'a mut [f64],
    du_re: &'a mut [f64],
    du_im: &'a mut [f64],
}

/// Fills submodel `i`'s numerator columns `u_t = x^(s+t) pi(x) / (x^l A(x))`, its
/// denominator columns `-x^t / A(x)` and the derivatives `d u_j / d a_t` (eq. 11-12 of the
/// wafer-stage paper) at every line. `z` is the discrete variable per line with the exact
/// hold (else the submodel's scaled `j w`), `f0_inv` the inverse known factor per line
/// (for a submodel that bypasses it), `dshape` the exact-hold shape's derivative.
fn fill_submodel(
    model: &AdditiveModel,
    i: usize,
    omega: &[f64],
    z: Option<&[C64]>,
    f0_inv: &[C64],
    dshape: Option<&[[f64; 2]; 2]>,
    c: SubmodelColumns<'_>,
) {
    let n = omega.len();
    let s = &model.submodels[i];
    let (nnum, nden) = (s.num.len(), s.den.len());
    for (k, &w) in omega.iter().enumerate() {
        let x = z.map_or_else(|| model.variable(s, w), |z| z[k]);
        let a = s.den_at(x);
        let pi_a = model.integrator_factor(s.integrators, x) * a;
        let mut pa = s.num_poly_at(x) / pi_a;
        if s.bypass_factor {
            // the divided problem sees this submodel divided by the known factor
            pa *= f0_inv[k];
        }
        let mut xr = x.powi(s.num_start as i32);
        for t in 0..nnum {
            let v = xr * pa;
            c.u_re[t * n + k] = v.re;
            c.u_im[t * n + k] = v.im;
            xr *= x;
        }
        let ia = a.inv();
        let mut xr = x;
        for t in 0..nden {
            let v = -xr * ia;
            c.d_re[t * n + k] = v.re;
            c.d_im[t * n + k] = v.im;
            // d u_j / d a_t = -x^t u_j / A (+ the shape's own derivative)
            for j in 0..nnum {
                let uj = C64::new(c.u_re[j * n + k], c.u_im[j * n + k]);
                let mut du = v * uj;
                if let Some(ds) = dshape {
                    let dc = C64::new(ds[t][0], 0.0) * x + C64::new(ds[t][1], 0.0) * x * x;
                    du += dc / pi_a;
                }
                let p = t * nnum + j;
                c.du_re[p * n + k] = du.re;
                c.du_im[p * n + k] = du.im;
            }
            xr *= x;
        }
    }
}

/// Per-entry work arrays over the lines: the divided data `y = G / F`, the scale
/// `s = sqrt(w) |F|` of the divided problem (`w |G - F P|^2 = s^2 |y - P|^2`), the
/// residual `E = y - sum_i P_i`, and the sum of the submodels that bypass the known
/// factor (the only per-submodel response the step needs; keeping every `P_i` would
/// make this fill bound by memory traffic).
#[derive(Default)]
pub struct EntryLines {
    /// `Re y`.
    pub y_re: Vec<f64>,
    /// `Im y`.
    pub y_im: Vec<f64>,
    /// `s = sqrt(w) |F|`.
    pub s: Vec<f64>,
    /// `Re sum_b P_b(k)` over the submodels `b` that bypass the known factor (empty
    /// when none does).
    pub pb_re: Vec<f64>,
    /// `Im sum_b P_b(k)`.
    pub pb_im: Vec<f64>,
    /// `Re E = Re (y - sum_i P_i)`.
    pub e_re: Vec<f64>,
    /// `Im E`.
    pub e_im: Vec<f64>,
}

/// Lines per block of [`EntryLines::fill`]'s residual: the block's `E` (2 x 4 kB) stays
/// in the L1 cache while the numerator basis streams past it.
const FILL_BLOCK: usize = 512;

impl EntryLines {
    /// Fills the arrays for entry `e` with numerators `be` (this entry's block of `eta`).
    /// `groups` lists `(first numerator index, count)` per submodel. The loops are
    /// compiled for the CPU's SIMD instruction set at run time (`pulp` dispatch).
    pub fn fill(
        &mut self,
        e: usize,
        data: &FitData,
        basis: &Basis,
        groups: &[(usize, usize)],
        be: &[f64],
    ) {
        /// The arguments, so that `with_simd` (inlined into pulp's `target_feature`
        /// function) runs the kernel with the CPU's instruction set.
        struct Op<'a> {
            el: &'a mut EntryLines,
            e: usize,
            data: &'a FitData,
            basis: &'a Basis,
            groups: &'a [(usize, usize)],
            be: &'a [f64],
        }
        impl pulp::WithSimd for Op<'_> {
            type Output = ();
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _simd: S) {
                self.el
                    .fill_kernel(self.e, self.data, self.basis, self.groups, self.be)
            }
        }
        pulp::Arch::new().dispatch(Op {
            el: self,
            e,
            data,
            basis,
            groups,
            be,
        })
    }

    #[inline(always)]
    fn fill_kernel(
        &mut self,
        e: usize,
        data: &FitData,
        basis: &Basis,
        groups: &[(usize, usize)],
        be: &[f64],
    ) {
        let n = data.n;
        let any_bypass = basis.bypass.iter().any(|&b| b);
        self.y_re.resize(n, 0.0);
        self.y_im.resize(n, 0.0);
        self.s.resize(n, 0.0);
        self.pb_re.clear();
        self.pb_re.resize(if any_bypass { n } else { 0 }, 0.0);
        self.pb_im.clear();
        self.pb_im.resize(self.pb_re.len(), 0.0);
        self.e_re.resize(n, 0.0);
        self.e_im.resize(n, 0.0);
        // slices cut to exactly `n`: no bounds checks, vectorised loops
        let gr = &data.g_re[e * n..][..n];
        let gi = &data.g_im[e * n..][..n];
        let sw = &data.sqrt_w[e * n..][..n];
        let fi = &basis.f_inv[basis.f_offset(e)..][..n];
        let fa = &basis.f_abs[basis.f_offset(e)..][..n];
        {
            let (yr, yi, s) = (&mut self.y_re[..n], &mut self.y_im[..n], &mut self.s[..n]);
            for k in 0..n {
                yr[k] = gr[k] * fi[k].re - gi[k] * fi[k].im;
                yi[k] = gr[k] * fi[k].im + gi[k] * fi[k].re;
                s[k] = sw[k] * fa[k];
            }
        }
        self.e_re.copy_from_slice(&self.y_re);
        self.e_im.copy_from_slice(&self.y_im);
        // E = y - sum_j b_j u_j, a block of lines at a time so that the block of E stays
        // in the L1 cache while the basis columns stream past it (each line sees the
        // same operations in the same order as one pass over all lines); zero
        // coefficients (the numerator fit starts from none) change nothing and are
        // skipped
        for b0 in (0..n).step_by(FILL_BLOCK) {
            let len = FILL_BLOCK.min(n - b0);
            let (er, ei) = (&mut self.e_re[b0..b0 + len], &mut self.e_im[b0..b0 + len]);
            for (i, &(off, cnt)) in groups.iter().enumerate() {
                let bypass = basis.bypass.get(i).copied().unwrap_or(false);
                for j in off..off + cnt {
                    let b = be[j];
                    if b == 0.0 {
                        continue;
                    }
                    let ur = &basis.u_re[j * n + b0..][..len];
                    let ui = &basis.u_im[j * n + b0..][..len];
                    for k in 0..len {
                        er[k] -= b * ur[k];
                        ei[k] -= b * ui[k];
                    }
                    if bypass {
                        let (pr, pi) =
                            (&mut self.pb_re[b0..b0 + len], &mut self.pb_im[b0..b0 + len]);
                        for k in 0..len {
                            pr[k] += b * ur[k];
                            pi[k] += b * ui[k];
                        }
                    }
                }
            }
        }
    }

    /// `sum_k s^2 |E|^2` of the entry.
    pub fn cost(&self) -> f64 {
        let mut c = 0.0;
        for k in 0..self.s.len() {
            c +=
                self.s[k] * self.s[k] * (self.e_re[k] * self.e_re[k] + self.e_im[k] * self.e_im[k]);
        }
        c
    }
}

/// `(first numerator index, count)` per submodel.
pub fn groups(model: &AdditiveModel, lay: &Layout) -> Vec<(usize, usize)> {
    model
        .submodels
        .iter()
        .enumerate()
        .map(|(i, s)| (lay.num_offset[i], s.num.len()))
        .collect()
}

/// Weighted cost `sum_k sum_e w |G - F P|^2` of `eta` given the basis, and optionally
/// the residual `E = G - F P` (in the data's line-major layout).
pub fn cost(
    data: &FitData,
    lay: &Layout,
    basis: &Basis,
    eta: &[f64],
    resid: Option<&mut Vec<C64>>,
    groups: &[(usize, usize)],
) -> f64 {
    let m = data.m();
    let n = data.n;
    let nn = lay.n_num;
    match resid {
        None => (0..m)
            .into_par_iter()
            .map_init(EntryLines::default, |el, e| {
                el.fill(e, data, basis, groups, &eta[e * nn..(e + 1) * nn]);
                el.cost()
            })
            .sum(),
        Some(r) => {
            // per entry on the rayon pool: its cost and its residual over the lines;
            // then summed in entry order (the same total as one thread would give)
            let per_entry: Vec<(f64, Vec<C64>)> = (0..m)
                .into_par_iter()
                .map_init(EntryLines::default, |el, e| {
                    el.fill(e, data, basis, groups, &eta[e * nn..(e + 1) * nn]);
                    let f = &basis.f[basis.f_offset(e)..basis.f_offset(e) + n];
                    // E of the undivided problem: F (y - P)
                    let col = f
                        .iter()
                        .zip(el.e_re.iter().zip(&el.e_im))
                        .map(|(fk, (re, im))| fk * C64::new(*re, *im))
                        .collect();
                    (el.cost(), col)
                })
                .collect();
            r.clear();
            r.resize(n * m, C64::new(0.0, 0.0));
            let mut total = 0.0;
            for (e, (c, col)) in per_entry.iter().enumerate() {
                total += c;
                for (k, v) in col.iter().enumerate() {
                    r[k * m + e] = *v;
                }
            }
            total
        }
    }
}
