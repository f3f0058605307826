//! A stabilising decoupling controller in rigid-body coordinates, as used for the
//! closed-loop experiments on the wafer stage (Section 4.2 of the wafer-stage paper: the
//! stage must be controlled to stay levitated, so the plant FRF is measured in closed
//! loop).
//!
//! The rigid-body residue is factored `b_rb = L R` (rank `r`, 3 for z, Rx, Ry) by the
//! SVD, `L = U S^(1/2)`, `R = S^(1/2) V^T`. The sensor transformation
//! `T_y = S^(-1/2) U^T` (`r x ny`) and the actuator transformation `T_u = V S^(-1/2)`
//! (`nu x r`) make `T_y b_rb T_u = I`: the rigid body is `r` decoupled unit double
//! integrators. Each gets the same SISO loop: PI + lead + second-order low-pass,
//! tuned for a crossover `bandwidth_hz`, discretised by the bilinear map with prewarping
//! at the crossover (McKelvey, eq. (39)). The MIMO controller is
//! `K(z) = T_u c(z) T_y` (`nu x ny`), and the loop is `u = r - K y_measured`.

use super::plant::{low_rank_factors, ModalPlant};
use faer::Mat;
use frf_data::{FrfError, C64};
use std::f64::consts::TAU;

/// Tuning of the rigid-body loops; `Default`: 20 Hz crossover.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    /// Crossover of each rigid-body loop, Hz.
    pub bandwidth_hz: f64,
    /// Integrator corner as a fraction of the crossover (0.2).
    pub integrator_fraction: f64,
    /// Lead: zero at `bandwidth / lead_ratio`, pole at `bandwidth * lead_ratio` (3).
    pub lead_ratio: f64,
    /// Low-pass corner as a multiple of the crossover (5).
    pub lowpass_factor: f64,
    /// Low-pass damping (0.5).
    pub lowpass_zeta: f64,
    /// Extra factor on the loop gain (1; larger values provoke instability in tests).
    pub gain_scale: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            bandwidth_hz: 20.0,
            integrator_fraction: 0.2,
            lead_ratio: 3.0,
            lowpass_factor: 5.0,
            lowpass_zeta: 0.5,
            gain_scale: 1.0,
        }
    }
}

/// A small real state-space model (the discrete SISO loop controller).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SmallSs {
    pub a: Vec<Vec<f64>>,
    pub b: Vec<f64>,
    pub c: Vec<f64>,
    pub d: f64,
}

impl SmallSs {
    fn n(&self) -> usize {
        self.b.len()
    }
    /// Series connection: `self` first, then `next`.
    fn then(&self, next: &SmallSs) -> SmallSs {
        let (n1, n2) = (self.n(), next.n());
        let n = n1 + n2;
        let mut a = vec![vec![0.0; n]; n];
        for i in 0..n1 {
            a[i][..n1].copy_from_slice(&self.a[i]);
        }
        for i in 0..n2 {
            for j in 0..n1 {
                a[n1 + i][j] = next.b[i] * self.c[j];
            }
            a[n1 + i][n1..].copy_from_slice(&next.a[i]);
        }
        let mut b = self.b.clone();
        b.extend(next.b.iter().map(|x| x * self.d));
        let mut c: Vec<f64> = self.c.iter().map(|x| x * next.d).collect();
        c.extend_from_slice(&next.c);
        SmallSs {
            a,
            b,
            c,
            d: next.d * self.d,
        }
    }
    /// Response at the complex point `x` (`s` or `z`): `d + c (x I - A)^-1 b`.
    pub fn eval(&self, x: C64) -> C64 {
        let n = self.n();
        let mut m: Vec<Vec<C64>> = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| {
                        let d = if i == j { x } else { C64::new(0.0, 0.0) };
                        d - self.a[i][j]
                    })
                    .collect()
            })
            .collect();
        let mut rhs: Vec<C64> = self.b.iter().map(|&v| C64::new(v, 0.0)).collect();
        solve_small(&mut m, &mut rhs);
        let mut out = C64::new(self.d, 0.0);
        for i in 0..n {
            out += rhs[i] * self.c[i];
        }
        out
    }
    /// The bilinear map `s = alpha (z - 1) / (z + 1)` in balanced form:
    /// `W = (alpha I - A)^-1`, `Ad = W (alpha I + A)`, `Bd = sqrt(2 alpha) W B`,
    /// `Cd = sqrt(2 alpha) C W`, `Dd = D + C W B`.
    fn bilinear(&self, alpha: f64) -> SmallSs {
        let n = self.n();
        // W by solving (alpha I - A) W = I column by column
        let mut w = vec![vec![0.0; n]; n];
        for col in 0..n {
            let mut m: Vec<Vec<C64>> = (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| {
                            let d = if i == j { alpha } else { 0.0 };
                            C64::new(d - self.a[i][j], 0.0)
                        })
                        .collect()
                })
                .collect();
            let mut e: Vec<C64> = (0..n)
                .map(|i| C64::new(if i == col { 1.0 } else { 0.0 }, 0.0))
                .collect();
            solve_small(&mut m, &mut e);
            for i in 0..n {
                w[i][col] = e[i].re;
            }
        }
        let mut ad = vec![vec![0.0; n]; n];
        for i in 0..n {
            for j in 0..n {
                let mut s = 0.0;
                for k in 0..n {
                    let apa = if k == j { alpha } else { 0.0 } + self.a[k][j];
                    s += w[i][k] * apa;
                }
                ad[i][j] = s;
            }
        }
        let g = (2.0 * alpha).sqrt();
        let wb: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|k| w[i][k] * self.b[k]).sum())
            .collect();
        let cw: Vec<f64> = (0..n)
            .map(|j| (0..n).map(|k| self.c[k] * w[k][j]).sum())
            .collect();
        let dd = self.d + (0..n).map(|i| self.c[i] * wb[i]).sum::<f64>();
        SmallSs {
            a: ad,
            b: wb.iter().map(|x| g * x).collect(),
            c: cw.iter().map(|x| g * x).collect(),
            d: dd,
        }
    }
}

/// Gaussian elimination with partial pivoting on a small dense complex system; the
/// solution replaces `rhs`. Singular pivots are left as they are (the callers only use
/// well-posed systems: `x I - A` off the poles).
pub(crate) fn solve_small(m: &mut [Vec<C64>], rhs: &mut [C64]) {
    let n = rhs.len();
    for k in 0..n {
        let mut p = k;
        for i in k + 1..n {
            if m[i][k].norm() > m[p][k].norm() {
                p = i;
            }
        }
        m.swap(k, p);
        rhs.swap(k, p);
        let piv = m[k][k];
        if piv.norm() == 0.0 {
            continue;
        }
        for i in k + 1..n {
            let f = m[i][k] / piv;
            if f.norm() == 0.0 {
                continue;
            }
            for j in k..n {
                let v = m[k][j];
                m[i][j] -= f * v;
            }
            let v = rhs[k];
            rhs[i] -= f * v;
        }
    }
    for k in (0..n).rev() {
        let mut s = rhs[k];
        for j in k + 1..n {
            s -= m[k][j] * rhs[j];
        }
        rhs[k] = if m[k][k].norm() == 0.0 {
            C64::new(0.0, 0.0)
        } else {
            s / m[k][k]
        };
    }
}

/// The MIMO rigid-body controller `K(z) = T_u c(z) T_y` (see the module documentation),
/// or no controller at all (open loop) for a plant without rigid body.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidBodyController {
    ny: usize,
    nu: usize,
    rank: usize,
    /// `r x ny`, row-major.
    t_y: Vec<f64>,
    /// `nu x r`, column-major (column q = actuator distribution of axis q).
    t_u: Vec<f64>,
    pub(crate) siso: SmallSs,
    /// The sample rate the controller was discretised for.
    pub fs: f64,
    /// The tuning it was designed with (`None` for the open-loop controller).
    pub config: Option<ControllerConfig>,
}

/// The state of a [`RigidBodyController`].
#[derive(Debug, Clone)]
pub struct ControllerState {
    x: Vec<f64>,
}

impl RigidBodyController {
    /// No feedback (`K = 0`): an open-loop experiment.
    pub fn open_loop(ny: usize, nu: usize, fs: f64) -> Self {
        Self {
            ny,
            nu,
            rank: 0,
            t_y: Vec::new(),
            t_u: Vec::new(),
            siso: SmallSs {
                a: Vec::new(),
                b: Vec::new(),
                c: Vec::new(),
                d: 0.0,
            },
            fs,
            config: None,
        }
    }

    /// Designs the decoupling controller for `plant` sampled at `fs` (see the module
    /// documentation). Fails when the plant has no rigid-body part (use
    /// [`RigidBodyController::open_loop`]) or the tuning is out of range. Stability of
    /// the resulting loop is checked by the experiment
    /// ([`crate::synth::ClosedLoopExperiment::new`]).
    pub fn design(
        plant: &ModalPlant,
        config: &ControllerConfig,
        fs: f64,
    ) -> Result<Self, FrfError> {
        let c = config;
        let pos = |name: &str, v: f64| -> Result<(), FrfError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(FrfError::invalid(name, v, "must be finite and > 0"))
            }
        };
        pos("fs", fs)?;
        pos("controller bandwidth_hz", c.bandwidth_hz)?;
        pos("controller integrator_fraction", c.integrator_fraction)?;
        pos("controller lowpass_factor", c.lowpass_factor)?;
        pos("controller lowpass_zeta", c.lowpass_zeta)?;
        pos("controller gain_scale", c.gain_scale)?;
        if !(c.lead_ratio.is_finite() && c.lead_ratio >= 1.0) {
            return Err(FrfError::invalid(
                "controller lead_ratio",
                c.lead_ratio,
                "must be finite and >= 1",
            ));
        }
        let top = c.bandwidth_hz * c.lead_ratio.max(c.lowpass_factor);
        if top >= 0.45 * fs {
            return Err(FrfError::invalid(
                "controller bandwidth_hz",
                c.bandwidth_hz,
                format!(
                    "its lead pole / low-pass ({top} Hz) must stay below 0.45 fs = {} Hz",
                    0.45 * fs
                ),
            ));
        }
        let residue = plant.rigid.residue().ok_or_else(|| {
            FrfError::invalid(
                "controller",
                "rigid-body decoupling",
                "the plant has no rigid-body part to decouple; use an open-loop experiment",
            )
        })?;
        let (ny, nu) = (plant.ny(), plant.nu());
        // b_rb = L R with L = U S, R = V^T: T_y = S^-1/2 U^T = S^1/2 (U S)^+ ... built
        // from the factors: with L = U S, T_y = S^-1/2 U^T = S^-3/2 L^T.
        let (l, r_rows, rank) = low_rank_factors(residue)?;
        if rank == 0 {
            return Err(FrfError::invalid(
                "controller",
                "rigid-body decoupling",
                "the rigid-body residue is zero",
            ));
        }
        let mut t_y = vec![0.0; rank * ny];
        let mut t_u = vec![0.0; nu * rank];
        for q in 0..rank {
            let col = &l[q * ny..(q + 1) * ny];
            let s = col.iter().map(|x| x * x).sum::<f64>().sqrt(); // = singular value
            for i in 0..ny {
                // U[:, q] = col / s, T_y row q = U[:, q]^T / sqrt(s)
                t_y[q * ny + i] = col[i] / s / s.sqrt();
            }
            for j in 0..nu {
                t_u[q * nu + j] = r_rows[q * nu + j] / s.sqrt();
            }
        }
        let wc = TAU * c.bandwidth_hz;
        let wi = wc * c.integrator_fraction;
        let wz = wc / c.lead_ratio;
        let wp = wc * c.lead_ratio;
        let wl = wc * c.lowpass_factor;
        let pi = SmallSs {
            a: vec![vec![0.0]],
            b: vec![1.0],
            c: vec![wi],
            d: 1.0,
        };
        let lead = SmallSs {
            a: vec![vec![-wp]],
            b: vec![1.0],
            c: vec![(wp / wz) * (wz - wp)],
            d: wp / wz,
        };
        let lp = SmallSs {
            a: vec![vec![0.0, wl], vec![-wl, -2.0 * c.lowpass_zeta * wl]],
            b: vec![0.0, wl],
            c: vec![1.0, 0.0],
            d: 0.0,
        };
        let mut cont = pi.then(&lead).then(&lp);
        // unit loop gain at crossover for the unit double integrator: |C(j wc)| = wc^2
        let mag = cont.eval(C64::new(0.0, wc)).norm();
        let k = c.gain_scale * wc * wc / mag;
        cont.c.iter_mut().for_each(|x| *x *= k);
        cont.d *= k;
        let ts = 1.0 / fs;
        let alpha = wc / (wc * ts / 2.0).tan();
        let siso = cont.bilinear(alpha);
        Ok(Self {
            ny,
            nu,
            rank,
            t_y,
            t_u,
            siso,
            fs,
            config: Some(config.clone()),
        })
    }

    /// Number of plant outputs (controller inputs).
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Number of plant inputs (controller outputs).
    pub fn nu(&self) -> usize {
        self.nu
    }
    /// Number of controlled rigid-body axes.
    pub fn rank(&self) -> usize {
        self.rank
    }
    /// Number of controller states.
    pub fn n_states(&self) -> usize {
        self.rank * self.siso.n()
    }

    /// The SISO loop controller `c(z)` at `z = exp(j 2 pi f / fs)`.
    pub fn siso_response(&self, f_hz: f64) -> C64 {
        if self.rank == 0 {
            return C64::new(0.0, 0.0);
        }
        self.siso.eval(C64::from_polar(1.0, TAU * f_hz / self.fs))
    }

    /// `vec(K)` (`nu x ny`, column-major) at `f_hz` into `out`.
    pub fn response_into(&self, f_hz: f64, out: &mut [C64]) {
        let (ny, nu) = (self.ny, self.nu);
        out.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
        if self.rank == 0 {
            return;
        }
        let cz = self.siso_response(f_hz);
        for i in 0..ny {
            for j in 0..nu {
                let mut s = 0.0;
                for q in 0..self.rank {
                    s += self.t_u[q * nu + j] * self.t_y[q * ny + i];
                }
                out[i * nu + j] = cz * s;
            }
        }
    }

    /// The controller at rest.
    pub fn zero_state(&self) -> ControllerState {
        ControllerState {
            x: vec![0.0; self.n_states()],
        }
    }

    /// The feedback force `-K y` for the measured output `y` into `u` (`nu`), and the
    /// state update.
    pub fn step(&self, x: &mut ControllerState, y: &[f64], u: &mut [f64]) {
        u.iter_mut().for_each(|v| *v = 0.0);
        if self.rank == 0 {
            return;
        }
        let (ny, nu, ns) = (self.ny, self.nu, self.siso.n());
        for q in 0..self.rank {
            let e: f64 = -(0..ny).map(|i| self.t_y[q * ny + i] * y[i]).sum::<f64>();
            let xs = &mut x.x[q * ns..(q + 1) * ns];
            let mut f = self.siso.d * e;
            for k in 0..ns {
                f += self.siso.c[k] * xs[k];
            }
            let old: Vec<f64> = xs.to_vec();
            for i in 0..ns {
                let mut s = self.siso.b[i] * e;
                for k in 0..ns {
                    s += self.siso.a[i][k] * old[k];
                }
                xs[i] = s;
            }
            for j in 0..nu {
                u[j] += self.t_u[q * nu + j] * f;
            }
        }
    }

    /// Real matrices `(A_k, B_k, C_k, D_k)` with `x' = A_k x + B_k y`,
    /// `u_feedback = C_k x + D_k y` (`D_k = -K(infinity)`, signs included).
    pub fn real_matrices(&self) -> (Mat<f64>, Mat<f64>, Mat<f64>, Mat<f64>) {
        let (ny, nu, ns, r) = (self.ny, self.nu, self.siso.n(), self.rank);
        let n = r * ns;
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, ny);
        let mut c = Mat::<f64>::zeros(nu, n);
        let mut d = Mat::<f64>::zeros(nu, ny);
        for q in 0..r {
            for i in 0..ns {
                for k in 0..ns {
                    a[(q * ns + i, q * ns + k)] = self.siso.a[i][k];
                }
                for m in 0..ny {
                    b[(q * ns + i, m)] = -self.siso.b[i] * self.t_y[q * ny + m];
                }
                for j in 0..nu {
                    c[(j, q * ns + i)] = self.t_u[q * nu + j] * self.siso.c[i];
                }
            }
            for j in 0..nu {
                for m in 0..ny {
                    d[(j, m)] -= self.t_u[q * nu + j] * self.siso.d * self.t_y[q * ny + m];
                }
            }
        }
        (a, b, c, d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_map_preserves_the_response_at_the_warped_frequency() {
        let wc = TAU * 20.0;
        let ss = SmallSs {
            a: vec![vec![0.0, wc], vec![-wc, -0.7 * wc]],
            b: vec![0.0, wc],
            c: vec![1.0, 0.3],
            d: 0.2,
        };
        let ts = 1e-4;
        let alpha = 2.0 / ts;
        let dss = ss.bilinear(alpha);
        for f in [1.0, 20.0, 300.0, 2000.0] {
            let wd = TAU * f * ts;
            let z = C64::from_polar(1.0, wd);
            let s = alpha * (z - 1.0) / (z + 1.0);
            let e = (dss.eval(z) - ss.eval(s)).norm() / ss.eval(s).norm();
            assert!(e < 1e-10, "f = {f}: {e}");
        }
    }
}
