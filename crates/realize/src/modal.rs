//! [`ModalModel`]: poles with residue matrices, a real rigid-body (integrator) part and a
//! feedthrough, and its exact frequency response in continuous time and through a
//! zero-order hold.

use crate::{RealizeError, ResponseGrid, C64};
use faer::Mat;
use serde::{Deserialize, Serialize};

/// Entries (`ny nu`) from which [`ModalModel::freq_response`] evaluates by matrix
/// products ([`ModalModel::fill_by_products`]); smaller models keep the line loop.
const PRODUCT_MIN_ENTRIES: usize = 100;
/// Terms (feedthrough, integrators, two per pair, one per real pole) from which the
/// products pay.
const PRODUCT_MIN_TERMS: usize = 8;
/// Lines per block (and per task on the rayon pool) of the products.
const PRODUCT_BLOCK_LINES: usize = 64;

/// One complex-conjugate pole pair `p, conj(p)` (with `Im p > 0`) and its residue `R`:
/// the pair contributes `R / (s - p) + conj(R) / (s - conj(p))`.
#[derive(Debug, Clone, PartialEq)]
pub struct PolePair {
    /// The pole in the upper half plane, rad/s.
    pub pole: C64,
    /// The complex `ny x nu` residue of `pole`.
    pub residue: Mat<C64>,
}

impl PolePair {
    /// Undamped natural frequency `|p|` in rad/s.
    pub fn omega_n(&self) -> f64 {
        self.pole.norm()
    }
    /// Natural frequency `|p| / 2 pi` in Hz.
    pub fn f_hz(&self) -> f64 {
        self.pole.norm() / std::f64::consts::TAU
    }
    /// Relative damping `-Re p / |p|`.
    pub fn zeta(&self) -> f64 {
        -self.pole.re / self.pole.norm()
    }
    /// The pair with natural frequency `f_hz` (Hz), damping `zeta` (0 <= zeta < 1) and
    /// residue `residue` of the upper pole.
    pub fn from_f_zeta(f_hz: f64, zeta: f64, residue: Mat<C64>) -> Self {
        let wn = std::f64::consts::TAU * f_hz;
        let pole = C64::new(-zeta * wn, wn * (1.0 - zeta * zeta).max(0.0).sqrt());
        Self { pole, residue }
    }
    /// The pair whose sum is `B / (s^2 + 2 zeta wn s + wn^2)` for a real constant numerator
    /// `B` (the flexible-mode form of eq. (26) of the wafer-stage paper, times `wn^2`):
    /// the residue is `B / (p - conj p) = B / (2 j wd)`.
    pub fn from_second_order(f_hz: f64, zeta: f64, numerator: &Mat<f64>) -> Self {
        let wn = std::f64::consts::TAU * f_hz;
        let wd = wn * (1.0 - zeta * zeta).max(0.0).sqrt();
        let pole = C64::new(-zeta * wn, wd);
        let scale = C64::new(0.0, -1.0 / (2.0 * wd));
        let residue = Mat::from_fn(numerator.nrows(), numerator.ncols(), |i, j| {
            scale * numerator[(i, j)]
        });
        Self { pole, residue }
    }
}

/// One real pole `p` with real residue `R`: contributes `R / (s - p)`.
#[derive(Debug, Clone, PartialEq)]
pub struct RealPole {
    /// The pole, rad/s (negative when stable).
    pub pole: f64,
    /// The real `ny x nu` residue.
    pub residue: Mat<f64>,
}

/// A continuous-time model in modal (partial-fraction) form:
///
/// `P(s) = sum_k rigid[k] / s^(k+1) + sum_pairs (R/(s-p) + conj(R)/(s-conj p))
///        + sum_real R/(s-p) + D`.
///
/// The rigid-body part is real; `rigid[1]` is the `1/s^2` coefficient of a free mass.
#[derive(Debug, Clone, PartialEq)]
pub struct ModalModel {
    /// Number of outputs.
    pub ny: usize,
    /// Number of inputs.
    pub nu: usize,
    /// `rigid[k]` is the real `ny x nu` coefficient of `1 / s^(k+1)`; empty when there
    /// are no poles at the origin.
    pub rigid: Vec<Mat<f64>>,
    /// Complex-conjugate pole pairs.
    pub pairs: Vec<PolePair>,
    /// Real poles (not at the origin).
    pub real_poles: Vec<RealPole>,
    /// Feedthrough `D` (`ny x nu`, zero when absent).
    pub feedthrough: Mat<f64>,
}

/// Summary of a pole pair for reports and JSON: frequency in Hz and damping.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModeSummary {
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Relative damping.
    pub zeta: f64,
}

impl ModalModel {
    /// An empty model (zero response) with `ny` outputs and `nu` inputs.
    pub fn new(ny: usize, nu: usize) -> Self {
        Self {
            ny,
            nu,
            rigid: Vec::new(),
            pairs: Vec::new(),
            real_poles: Vec::new(),
            feedthrough: Mat::zeros(ny, nu),
        }
    }

    /// Checks that every matrix has shape `ny x nu` and every value is finite.
    pub fn validate(&self) -> Result<(), RealizeError> {
        let shape = |what: &str, r: usize, c: usize| -> Result<(), RealizeError> {
            if r != self.ny || c != self.nu {
                return Err(RealizeError::Dimension {
                    what: what.to_string(),
                    expected: format!("{}x{}", self.ny, self.nu),
                    got: format!("{r}x{c}"),
                });
            }
            Ok(())
        };
        for (k, r) in self.rigid.iter().enumerate() {
            shape(&format!("rigid[{k}]"), r.nrows(), r.ncols())?;
            if !all_finite_real(r) {
                return Err(RealizeError::NonFinite {
                    what: format!("rigid[{k}]"),
                });
            }
        }
        for (k, p) in self.pairs.iter().enumerate() {
            shape(
                &format!("pairs[{k}].residue"),
                p.residue.nrows(),
                p.residue.ncols(),
            )?;
            if !(p.pole.re.is_finite() && p.pole.im.is_finite() && all_finite_complex(&p.residue)) {
                return Err(RealizeError::NonFinite {
                    what: format!("pairs[{k}]"),
                });
            }
        }
        for (k, p) in self.real_poles.iter().enumerate() {
            shape(
                &format!("real_poles[{k}].residue"),
                p.residue.nrows(),
                p.residue.ncols(),
            )?;
            if !p.pole.is_finite() || !all_finite_real(&p.residue) {
                return Err(RealizeError::NonFinite {
                    what: format!("real_poles[{k}]"),
                });
            }
        }
        shape(
            "feedthrough",
            self.feedthrough.nrows(),
            self.feedthrough.ncols(),
        )?;
        if !all_finite_real(&self.feedthrough) {
            return Err(RealizeError::NonFinite {
                what: "feedthrough".into(),
            });
        }
        Ok(())
    }

    /// Natural frequencies and damping of the pole pairs, in the stored order.
    pub fn mode_summaries(&self) -> Vec<ModeSummary> {
        self.pairs
            .iter()
            .map(|p| ModeSummary {
                f_hz: p.f_hz(),
                zeta: p.zeta(),
            })
            .collect()
    }

    /// True when every pole is in the open left half plane (the integrators of the
    /// rigid-body part excepted).
    pub fn is_stable(&self) -> bool {
        self.pairs.iter().all(|p| p.pole.re < 0.0) && self.real_poles.iter().all(|p| p.pole < 0.0)
    }

    /// `vec(P(s))` at one complex point `s` into `out` (length `ny * nu`), column-major.
    pub fn eval_s_into(&self, s: C64, out: &mut [C64]) {
        let (ny, nu) = (self.ny, self.nu);
        debug_assert_eq!(out.len(), ny * nu);
        for j in 0..nu {
            for i in 0..ny {
                out[j * ny + i] = C64::new(self.feedthrough[(i, j)], 0.0);
            }
        }
        if !self.rigid.is_empty() {
            let inv_s = s.inv();
            let mut pw = inv_s;
            for r in &self.rigid {
                for j in 0..nu {
                    for i in 0..ny {
                        out[j * ny + i] += pw * r[(i, j)];
                    }
                }
                pw *= inv_s;
            }
        }
        for p in &self.pairs {
            let f1 = (s - p.pole).inv();
            let f2 = (s - p.pole.conj()).inv();
            // r f1 + conj(r) f2 = Re r (f1 + f2) + Im r j (f1 - f2)
            let (sum, dif) = (f1 + f2, C64::new(0.0, 1.0) * (f1 - f2));
            for j in 0..nu {
                let col = p.residue.col_as_slice(j);
                for (o, r) in out[j * ny..(j + 1) * ny].iter_mut().zip(col) {
                    *o += sum * r.re + dif * r.im;
                }
            }
        }
        for p in &self.real_poles {
            let f = (s - p.pole).inv();
            for j in 0..nu {
                for i in 0..ny {
                    out[j * ny + i] += f * p.residue[(i, j)];
                }
            }
        }
    }

    /// [`ModalModel::freq_response`] of a large model as matrix products: every term
    /// is a real coefficient per entry times a complex function of `s` common to all
    /// entries (the feedthrough 1, the rigid body `s^-k`, a pair's `f1 + f2` and
    /// `j (f1 - f2)` with `f1 = 1/(s - p)`, `f2 = 1/(s - conj p)`, a real pole's
    /// `1/(s - p)`), so a block of lines is `X^T B` with `X` the coefficients (terms x
    /// entries) and `B` the functions (terms x lines), real and imaginary parts apart.
    /// The coefficients are read once per block instead of once per line: the line
    /// loop of [`ModalModel::eval_s_into`] streams every residue matrix for every line.
    fn fill_by_products(&self, omega: &[f64], g: &mut ResponseGrid) {
        use faer::linalg::matmul::matmul;
        use faer::{Accum, Par};
        use rayon::prelude::*;
        let (ny, nu) = (self.ny, self.nu);
        let m = ny * nu;
        let nt = 1 + self.rigid.len() + 2 * self.pairs.len() + self.real_poles.len();
        // X^T: entries x terms, in the order of the functions below
        let xt = Mat::<f64>::from_fn(m, nt, |e, t| {
            let (i, j) = (e % ny, e / ny);
            let mut t = t;
            if t == 0 {
                return self.feedthrough[(i, j)];
            }
            t -= 1;
            if t < self.rigid.len() {
                return self.rigid[t][(i, j)];
            }
            t -= self.rigid.len();
            if t < 2 * self.pairs.len() {
                let r = self.pairs[t / 2].residue[(i, j)];
                return if t % 2 == 0 { r.re } else { r.im };
            }
            t -= 2 * self.pairs.len();
            self.real_poles[t].residue[(i, j)]
        });
        g.values
            .par_chunks_mut(PRODUCT_BLOCK_LINES * m)
            .enumerate()
            .for_each(|(b, block)| {
                let k0 = b * PRODUCT_BLOCK_LINES;
                let nb = block.len() / m;
                let mut bre = Mat::<f64>::zeros(nt, nb);
                let mut bim = Mat::<f64>::zeros(nt, nb);
                for c in 0..nb {
                    let s = C64::new(0.0, omega[k0 + c]);
                    let mut put = |t: usize, v: C64| {
                        bre[(t, c)] = v.re;
                        bim[(t, c)] = v.im;
                    };
                    put(0, C64::new(1.0, 0.0));
                    let mut t = 1;
                    if !self.rigid.is_empty() {
                        let inv_s = s.inv();
                        let mut pw = inv_s;
                        for _ in &self.rigid {
                            put(t, pw);
                            pw *= inv_s;
                            t += 1;
                        }
                    }
                    for p in &self.pairs {
                        let f1 = (s - p.pole).inv();
                        let f2 = (s - p.pole.conj()).inv();
                        put(t, f1 + f2);
                        put(t + 1, C64::new(0.0, 1.0) * (f1 - f2));
                        t += 2;
                    }
                    for p in &self.real_poles {
                        put(t, (s - p.pole).inv());
                        t += 1;
                    }
                }
                let mut pre = Mat::<f64>::zeros(m, nb);
                let mut pim = Mat::<f64>::zeros(m, nb);
                matmul(
                    pre.as_mut(),
                    Accum::Replace,
                    xt.as_ref(),
                    bre.as_ref(),
                    1.0,
                    Par::Seq,
                );
                matmul(
                    pim.as_mut(),
                    Accum::Replace,
                    xt.as_ref(),
                    bim.as_ref(),
                    1.0,
                    Par::Seq,
                );
                for (c, line) in block.chunks_mut(m).enumerate() {
                    for (e, v) in line.iter_mut().enumerate() {
                        *v = C64::new(pre[(e, c)], pim[(e, c)]);
                    }
                }
            });
    }

    /// The continuous-time frequency response `P(j w)` at the angular frequencies
    /// `omega` (rad/s). Fails at `w = 0` when the model has integrators, and when the
    /// model does not pass [`ModalModel::validate`].
    pub fn freq_response(&self, omega: &[f64]) -> Result<ResponseGrid, RealizeError> {
        self.validate()?;
        if !self.rigid.is_empty() {
            if let Some(k) = omega.iter().position(|&w| w == 0.0) {
                return Err(RealizeError::AtPole {
                    point: k,
                    omega: 0.0,
                });
            }
        }
        let mut g = ResponseGrid::zeros(omega.len(), self.ny, self.nu);
        let terms = self.pairs.len() * 2 + self.real_poles.len() + self.rigid.len() + 1;
        if self.ny * self.nu >= PRODUCT_MIN_ENTRIES && terms >= PRODUCT_MIN_TERMS {
            self.fill_by_products(omega, &mut g);
            return Ok(g);
        }
        g.fill_lines(8 * terms * self.ny * self.nu, |k, line| {
            self.eval_s_into(C64::new(0.0, omega[k]), line)
        });
        Ok(g)
    }

    /// The exact frequency response of this continuous model seen through a zero-order
    /// hold sampler with sample time `ts` and an extra delay of `delay_samples` samples
    /// (e.g. 1.0 for one sample of computation delay), evaluated at
    /// `z = exp(j w ts)` for each `w` in `omega` (rad/s).
    ///
    /// Every term is discretized in closed form: `R/(s-p)` becomes
    /// `R (e^{p ts} - 1)/p / (z - e^{p ts})`, and `R/s^k` becomes
    /// `R ts^k/k! E_k(z)/(z-1)^k` with `E_k` the Eulerian polynomial (`E_2 = z + 1`), the
    /// same transfer function that the augmented-matrix-exponential discretization gives.
    pub fn zoh_response(
        &self,
        omega: &[f64],
        ts: f64,
        delay_samples: f64,
    ) -> Result<ResponseGrid, RealizeError> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(RealizeError::InvalidParameter {
                name: "ts".into(),
                value: ts,
                why: "the sample time must be finite and > 0".into(),
            });
        }
        self.validate()?;
        let (ny, nu) = (self.ny, self.nu);
        let mut g = ResponseGrid::zeros(omega.len(), ny, nu);
        // Per-term discrete gains, computed once.
        let pair_terms: Vec<(C64, C64)> = self
            .pairs
            .iter()
            .map(|p| zoh_first_order(p.pole, ts))
            .collect();
        let real_terms: Vec<(C64, C64)> = self
            .real_poles
            .iter()
            .map(|p| zoh_first_order(C64::new(p.pole, 0.0), ts))
            .collect();
        let euler: Vec<Vec<f64>> = (1..=self.rigid.len()).map(eulerian_row).collect();
        for (k, &w) in omega.iter().enumerate() {
            let z = C64::from_polar(1.0, w * ts);
            let out = g.line_mut(k);
            for j in 0..nu {
                for i in 0..ny {
                    out[j * ny + i] = C64::new(self.feedthrough[(i, j)], 0.0);
                }
            }
            if !self.rigid.is_empty() {
                let zm1 = z - 1.0;
                if zm1.norm() < 1e-300 {
                    return Err(RealizeError::AtPole { point: k, omega: w });
                }
                let mut fact = 1.0;
                for (order_m1, r) in self.rigid.iter().enumerate() {
                    let kk = order_m1 + 1;
                    fact *= kk as f64;
                    // E_k(z) by Horner, highest power first.
                    let mut e = C64::new(0.0, 0.0);
                    for &c in &euler[order_m1] {
                        e = e * z + c;
                    }
                    let gain = e * ts.powi(kk as i32) / fact / zm1.powi(kk as i32);
                    for j in 0..nu {
                        for i in 0..ny {
                            out[j * ny + i] += gain * r[(i, j)];
                        }
                    }
                }
            }
            for (p, &(num, zp)) in self.pairs.iter().zip(&pair_terms) {
                let f1 = num / (z - zp);
                let f2 = num.conj() / (z - zp.conj());
                for j in 0..nu {
                    for i in 0..ny {
                        let r = p.residue[(i, j)];
                        out[j * ny + i] += r * f1 + r.conj() * f2;
                    }
                }
            }
            for (p, &(num, zp)) in self.real_poles.iter().zip(&real_terms) {
                let f = num / (z - zp);
                for j in 0..nu {
                    for i in 0..ny {
                        out[j * ny + i] += f * p.residue[(i, j)];
                    }
                }
            }
            if delay_samples != 0.0 {
                let d = C64::from_polar(1.0, -w * ts * delay_samples);
                for v in out.iter_mut() {
                    *v *= d;
                }
            }
        }
        Ok(g)
    }
}

/// ZOH discretization of `1/(s - p)`: returns `((e^{p ts} - 1)/p, e^{p ts})` so that the
/// discrete term is `num / (z - zp)`; the limit `p -> 0` gives `ts`.
fn zoh_first_order(p: C64, ts: f64) -> (C64, C64) {
    let zp = (p * ts).exp();
    let x = p * ts;
    // (e^x - 1)/x * ts, accurate for small |x| by its series.
    let num = if x.norm() < 1e-5 {
        ts * (C64::new(1.0, 0.0) + x / 2.0 + x * x / 6.0)
    } else {
        (zp - 1.0) / p
    };
    (num, zp)
}

/// Eulerian numbers `A(k, m)`, `m = 0..k-1`: the coefficients (highest power of `z`
/// first) of the polynomial `E_k(z)` in `Z{zoh(1/s^k)} = ts^k/k! E_k(z) / (z-1)^k`.
fn eulerian_row(k: usize) -> Vec<f64> {
    let mut row = vec![1.0];
    for n in 2..=k {
        let mut next = vec![0.0; n];
        for m in 0..n {
            let a = if m >= 1 && m - 1 < row.len() {
                (n - m) as f64 * row[m - 1]
            } else {
                0.0
            };
            let b = if m < row.len() {
                (m + 1) as f64 * row[m]
            } else {
                0.0
            };
            next[m] = a + b;
        }
        row = next;
    }
    row
}

fn all_finite_real(m: &Mat<f64>) -> bool {
    (0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite()))
}

fn all_finite_complex(m: &Mat<C64>) -> bool {
    (0..m.ncols())
        .all(|j| (0..m.nrows()).all(|i| m[(i, j)].re.is_finite() && m[(i, j)].im.is_finite()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The products of a large model give the line loop's response to rounding.
    #[test]
    fn the_response_by_products_is_the_line_loop_response() {
        let (ny, nu) = (10, 12);
        let mut m = ModalModel::new(ny, nu);
        let val = |a: usize, i: usize, j: usize| ((a * 31 + i * 7 + j * 3) as f64 * 0.173).sin();
        for q in 0..6 {
            let wn = 30.0 + 25.0 * q as f64;
            m.pairs.push(PolePair {
                pole: C64::new(-0.01 * wn, wn),
                residue: Mat::from_fn(ny, nu, |i, j| C64::new(val(q, i, j), val(q + 9, i, j))),
            });
        }
        m.real_poles.push(RealPole {
            pole: -40.0,
            residue: Mat::from_fn(ny, nu, |i, j| val(20, i, j)),
        });
        m.rigid = (0..2)
            .map(|k| Mat::from_fn(ny, nu, |i, j| 1e3 * val(30 + k, i, j)))
            .collect();
        m.feedthrough = Mat::from_fn(ny, nu, |i, j| val(40, i, j));
        assert!(ny * nu >= PRODUCT_MIN_ENTRIES);
        let omega: Vec<f64> = (0..150).map(|k| 5.0 + 1.7 * k as f64).collect();
        let g = m.freq_response(&omega).unwrap();
        let mut line = vec![C64::new(0.0, 0.0); ny * nu];
        for (k, &w) in omega.iter().enumerate() {
            m.eval_s_into(C64::new(0.0, w), &mut line);
            let scale = line.iter().map(|v| v.norm()).fold(0.0, f64::max);
            for (a, b) in g.line(k).iter().zip(&line) {
                assert!((a - b).norm() <= 1e-13 * scale, "line {k}: {a} against {b}");
            }
        }
    }

    #[test]
    fn eulerian_rows() {
        assert_eq!(eulerian_row(1), vec![1.0]);
        assert_eq!(eulerian_row(2), vec![1.0, 1.0]);
        assert_eq!(eulerian_row(3), vec![1.0, 4.0, 1.0]);
        assert_eq!(eulerian_row(4), vec![1.0, 11.0, 11.0, 1.0]);
    }

    #[test]
    fn double_integrator_zoh_closed_form() {
        // zoh(1/s^2) = ts^2 (z+1) / (2 (z-1)^2)
        let mut m = ModalModel::new(1, 1);
        m.rigid = vec![Mat::zeros(1, 1), Mat::from_fn(1, 1, |_, _| 1.0)];
        let ts = 1e-4;
        let w = [100.0, 3000.0, 20000.0];
        let g = m.zoh_response(&w, ts, 0.0).unwrap();
        for (k, &wk) in w.iter().enumerate() {
            let z = C64::from_polar(1.0, wk * ts);
            let expect = (z + 1.0) * ts * ts / (2.0 * (z - 1.0) * (z - 1.0));
            assert!((g.get(k, 0, 0) - expect).norm() < 1e-12 * expect.norm());
        }
    }
}
