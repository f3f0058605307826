//! Exact zero-order-hold (ZOH) discretization of a continuous state-space model and the
//! frequency response of the sampled model with an extra delay.
//!
//! Conventions (shared with [`crate::ModalModel::zoh_response`]): the input is held
//! constant over each sample interval of length `ts`; the discrete model is
//! `x[k+1] = Ad x[k] + Bd u[k], y[k] = C x[k] + D u[k]` with `Ad = e^{A ts}` and
//! `Bd = int_0^ts e^{A t} dt B`, both read off one exponential of the augmented matrix
//! (Van Loan 1978):
//!
//! `expm([[A, B], [0, 0]] ts) = [[Ad, Bd], [0, I]]`.
//!
//! The response "seen through a ZOH sampler at sample time `ts` with an extra delay of
//! `d` samples" is `H_zoh(z) z^-d` at `z = exp(j w ts)`.

use crate::expm::expm;
use crate::{RealizeError, ResponseGrid, StateSpace, TimeDomain, C64};
use faer::Mat;

fn check_ts(ts: f64) -> Result<(), RealizeError> {
    if ts.is_finite() && ts > 0.0 {
        Ok(())
    } else {
        Err(RealizeError::InvalidParameter {
            name: "ts".into(),
            value: ts,
            why: "the sample time must be finite and > 0".into(),
        })
    }
}

/// Exact ZOH discretization of the continuous model `ss` with sample time `ts` by the
/// augmented matrix exponential (Van Loan 1978; exponential by Higham 2005). Fails with
/// [`RealizeError::WrongDomain`] for a discrete model.
pub fn discretize_zoh(ss: &StateSpace, ts: f64) -> Result<StateSpace, RealizeError> {
    ss.validate()?;
    if ss.domain != TimeDomain::Continuous {
        return Err(RealizeError::WrongDomain {
            op: "discretize_zoh".into(),
            needed: "continuous-time".into(),
        });
    }
    check_ts(ts)?;
    let (n, nu) = (ss.n_states(), ss.nu());
    let m = Mat::from_fn(n + nu, n + nu, |i, j| {
        if i >= n {
            0.0
        } else if j < n {
            ss.a[(i, j)] * ts
        } else {
            ss.b[(i, j - n)] * ts
        }
    });
    let e = expm(m.as_ref())?;
    let ad = Mat::from_fn(n, n, |i, j| e[(i, j)]);
    let bd = Mat::from_fn(n, nu, |i, j| e[(i, n + j)]);
    StateSpace::new(
        ad,
        bd,
        ss.c.clone(),
        ss.d.clone(),
        TimeDomain::Discrete { ts },
    )
}

/// `H_zoh(z) z^-d` at `z = exp(j w ts)` for each `w` in `omega` (rad/s), where `H_zoh` is
/// the transfer function of [`discretize_zoh`]`(ss, ts)` and `d = delay_samples`.
pub fn zoh_response(
    ss: &StateSpace,
    omega: &[f64],
    ts: f64,
    delay_samples: usize,
) -> Result<ResponseGrid, RealizeError> {
    let sd = discretize_zoh(ss, ts)?;
    let mut g = sd.freq_response(omega)?;
    apply_delay(&mut g, omega, ts, delay_samples as f64);
    Ok(g)
}

/// Multiplies every line `k` of `g` by `z^-d = exp(-j w_k ts d)`.
pub(crate) fn apply_delay(g: &mut ResponseGrid, omega: &[f64], ts: f64, d: f64) {
    if d == 0.0 {
        return;
    }
    for (k, &w) in omega.iter().enumerate() {
        let f = C64::from_polar(1.0, -w * ts * d);
        for v in g.line_mut(k) {
            *v *= f;
        }
    }
}
