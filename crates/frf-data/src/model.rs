//! The [`ModelStructure`] trait: a parametrised model family.

use crate::{FrfDataset, FrfError, C64};
use realize::{FrfModel, ModalModel, ResponseGrid};

/// A parametrised model family `P(s, theta)` with `ny` outputs and `nu` inputs.
///
/// The frequency response includes any *known factor* the model carries (a delay, a
/// zero-order hold), so that [`ModelStructure::response`] compares directly with the
/// data it was fitted to. [`ModelStructure::to_modal`] gives the rational part in
/// `realize` form (the known factor is not rational and is left out; the model says so
/// in its own documentation).
pub trait ModelStructure: Clone + Send + Sync {
    /// Number of outputs.
    fn ny(&self) -> usize;
    /// Number of inputs.
    fn nu(&self) -> usize;
    /// Number of free real parameters.
    fn n_params(&self) -> usize;
    /// The parameter vector (in the model's documented order and scaling).
    fn params(&self) -> Vec<f64>;
    /// Sets the parameter vector; fails when the length is wrong or a value is invalid.
    fn set_params(&mut self, params: &[f64]) -> Result<(), FrfError>;
    /// `vec(P(j w))` (column-major, length `ny * nu`) at angular frequency `omega`
    /// (rad/s), known factors included.
    fn response_into(&self, omega: f64, out: &mut [C64]);
    /// The rational part of the model as a [`ModalModel`].
    fn to_modal(&self) -> Result<ModalModel, FrfError>;
    /// The model in the chain's currency ([`FrfModel`]: the rational part with its known
    /// factors), which every refiner accepts and every file and report uses.
    fn to_frf_model(&self) -> Result<FrfModel, FrfError>;

    /// The response at the angular frequencies `omega` (rad/s).
    fn response_at(&self, omega: &[f64]) -> ResponseGrid {
        let mut g = ResponseGrid::zeros(omega.len(), self.ny(), self.nu());
        for (k, &w) in omega.iter().enumerate() {
            self.response_into(w, g.line_mut(k));
        }
        g
    }

    /// The response at the lines of `data`.
    fn response<D: FrfDataset + ?Sized>(&self, data: &D) -> ResponseGrid
    where
        Self: Sized,
    {
        self.response_at(&data.omegas())
    }

    /// Jacobian of `vec(P(j w))` with respect to the parameters at `omega`, into `jac`
    /// (column-major, `(ny * nu) x n_params`, column `p` is `d vec(P) / d theta_p`).
    ///
    /// The default is a central finite difference with step
    /// `h_p = 1e-6 * max(|theta_p|, 1e-6)`; models with a cheap analytic Jacobian
    /// override it.
    fn jacobian_into(&self, omega: f64, jac: &mut [C64]) {
        let m = self.ny() * self.nu();
        let theta = self.params();
        let mut work = self.clone();
        let mut plus = vec![C64::new(0.0, 0.0); m];
        let mut minus = vec![C64::new(0.0, 0.0); m];
        let mut t = theta.clone();
        for p in 0..theta.len() {
            let h = 1e-6 * theta[p].abs().max(1e-6);
            t[p] = theta[p] + h;
            let ok_plus = work.set_params(&t).is_ok();
            work.response_into(omega, &mut plus);
            t[p] = theta[p] - h;
            let ok_minus = work.set_params(&t).is_ok();
            work.response_into(omega, &mut minus);
            t[p] = theta[p];
            let col = &mut jac[p * m..(p + 1) * m];
            if ok_plus && ok_minus {
                for e in 0..m {
                    col[e] = (plus[e] - minus[e]) / (2.0 * h);
                }
            } else {
                col.fill(C64::new(f64::NAN, f64::NAN));
            }
        }
    }
}
