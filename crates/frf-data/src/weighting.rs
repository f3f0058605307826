//! Weightings of the least-squares criterion (8) of the wafer-stage paper:
//! `V = sum_k sum_e w[k][e] |E_e(w_k)|^2`, one non-negative weight per line `k` and
//! entry `e` of `vec(G)`.

use crate::{FrfDataset, FrfError};
use std::sync::Arc;

/// How to weight the residual of each line and entry.
#[derive(Debug, Clone, Default, PartialEq)]
pub enum Weighting {
    /// [`Weighting::InverseVariance`] when the data carry a variance, otherwise
    /// [`Weighting::InverseMagnitude`] (the default).
    #[default]
    Auto,
    /// Element-wise inverse magnitude, eq. (27) of the wafer-stage paper, applied to the
    /// residual: the weighted residual is `E / |G|`, the relative error that the paper
    /// describes, so `w = 1 / |G|^2`. Magnitudes are floored at `1e-4` times the entry's
    /// median magnitude so that a deep anti-resonance or an exact zero cannot take all
    /// the weight.
    InverseMagnitude,
    /// `w = 1 / var` from the `_var` columns: with the estimate's variance, the weighted
    /// least-squares criterion is the (Gaussian) maximum-likelihood criterion.
    /// Variances are floored at `1e-6` times the entry's median variance.
    InverseVariance,
    /// `w = 1` (plain least squares).
    Uniform,
    /// User-supplied weights, one per line and entry in the layout of
    /// [`FrfDataset::values_vec`] (line after line, each line `vec(G)`).
    User(Arc<Vec<f64>>),
}

impl Weighting {
    /// The concrete weighting `Auto` resolves to for `data`.
    pub fn resolve<D: FrfDataset + ?Sized>(&self, data: &D) -> Weighting {
        match self {
            Weighting::Auto if data.has_variance() => Weighting::InverseVariance,
            Weighting::Auto => Weighting::InverseMagnitude,
            w => w.clone(),
        }
    }

    /// A short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            Weighting::Auto => "auto",
            Weighting::InverseMagnitude => "inverse magnitude (eq. 27)",
            Weighting::InverseVariance => "inverse variance (maximum likelihood)",
            Weighting::Uniform => "uniform",
            Weighting::User(_) => "user-supplied",
        }
    }

    /// The weights for `data`, line after line, each line in `vec(G)` order.
    ///
    /// Fails when inverse-variance weighting is asked of data without variance, when
    /// user weights have the wrong length or a negative or non-finite value, and when
    /// every weight is zero.
    pub fn weights<D: FrfDataset + ?Sized>(&self, data: &D) -> Result<Vec<f64>, FrfError> {
        let n = data.n_lines();
        let m = data.n_entries();
        let w = match self.resolve(data) {
            Weighting::Uniform => vec![1.0; n * m],
            Weighting::InverseMagnitude => {
                let vals = data.values_vec();
                let floors = per_entry_floor(n, m, |idx| vals[idx].norm(), 1e-4);
                let mut w = Vec::with_capacity(n * m);
                for idx in 0..n * m {
                    let a = vals[idx].norm().max(floors[idx % m]);
                    w.push(if a > 0.0 { 1.0 / (a * a) } else { 0.0 });
                }
                w
            }
            Weighting::InverseVariance => {
                let var = data.variance_vec().ok_or_else(|| FrfError::NoVariance {
                    what: "inverse-variance weighting".into(),
                })?;
                let floors = per_entry_floor(n, m, |idx| var[idx], 1e-6);
                let mut w = Vec::with_capacity(n * m);
                for idx in 0..n * m {
                    let v = var[idx].max(floors[idx % m]);
                    w.push(if v > 0.0 { 1.0 / v } else { 0.0 });
                }
                w
            }
            Weighting::User(u) => {
                if u.len() != n * m {
                    return Err(FrfError::Dimension {
                        what: "user weights".into(),
                        expected: format!("{} ({n} lines x {m} entries)", n * m),
                        got: u.len().to_string(),
                    });
                }
                if let Some((idx, x)) = u
                    .iter()
                    .enumerate()
                    .find(|(_, x)| !x.is_finite() || **x < 0.0)
                {
                    return Err(FrfError::invalid(
                        "user weight",
                        x,
                        format!(
                            "at line {} entry {}: weights must be finite and >= 0",
                            idx / m,
                            idx % m
                        ),
                    ));
                }
                u.as_ref().clone()
            }
            Weighting::Auto => unreachable!("resolved above"),
        };
        if w.iter().all(|&x| x == 0.0) {
            return Err(FrfError::invalid(
                "weighting",
                self.name(),
                "every weight is zero: nothing to fit",
            ));
        }
        Ok(w)
    }
}

/// Per-entry floor: `rel` times the median over lines of `value(k * m + e)` for each
/// entry `e` (0 when the median is 0).
fn per_entry_floor(n: usize, m: usize, value: impl Fn(usize) -> f64, rel: f64) -> Vec<f64> {
    let mut floors = vec![0.0; m];
    let mut col = Vec::with_capacity(n);
    for (e, fl) in floors.iter_mut().enumerate() {
        col.clear();
        col.extend((0..n).map(|k| value(k * m + e)));
        col.sort_by(|a, b| a.total_cmp(b));
        let med = if n == 0 { 0.0 } else { col[n / 2] };
        *fl = rel * med;
    }
    floors
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Frf, C64};

    fn small(with_var: bool) -> Frf {
        let f = vec![1.0, 2.0, 3.0];
        let vals = vec![C64::new(2.0, 0.0), C64::new(0.0, 4.0), C64::new(1.0, 0.0)];
        let var = with_var.then(|| vec![0.5, 0.25, 0.0]);
        Frf::new(f, 1, 1, vals, var).unwrap()
    }

    #[test]
    fn inverse_magnitude_is_relative_error() {
        let w = Weighting::InverseMagnitude.weights(&small(false)).unwrap();
        assert!((w[0] - 0.25).abs() < 1e-15);
        assert!((w[1] - 1.0 / 16.0).abs() < 1e-15);
    }

    #[test]
    fn auto_picks_variance_when_present() {
        let d = small(true);
        assert_eq!(Weighting::Auto.resolve(&d), Weighting::InverseVariance);
        let w = Weighting::Auto.weights(&d).unwrap();
        assert!((w[0] - 2.0).abs() < 1e-12);
        // zero variance is floored, not infinite
        assert!(w[2].is_finite());
        assert_eq!(
            Weighting::Auto.resolve(&small(false)),
            Weighting::InverseMagnitude
        );
    }

    #[test]
    fn inverse_variance_without_variance_fails() {
        let e = Weighting::InverseVariance
            .weights(&small(false))
            .unwrap_err();
        assert!(matches!(e, FrfError::NoVariance { .. }));
    }

    #[test]
    fn user_weights_are_checked() {
        let d = small(false);
        assert!(Weighting::User(Arc::new(vec![1.0, 2.0]))
            .weights(&d)
            .is_err());
        assert!(Weighting::User(Arc::new(vec![1.0, -2.0, 1.0]))
            .weights(&d)
            .is_err());
        let e = Weighting::User(Arc::new(vec![0.0; 3]))
            .weights(&d)
            .unwrap_err();
        assert!(e.to_string().contains("every weight is zero"), "{e}");
        assert_eq!(
            Weighting::User(Arc::new(vec![1.0, 0.5, 0.0]))
                .weights(&d)
                .unwrap(),
            vec![1.0, 0.5, 0.0]
        );
    }
}
