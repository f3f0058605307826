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
        // the (n/2)-th smallest in the total order, without sorting the rest
        let med = if n == 0 {
            0.0
        } else {
            *col.select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b)).1
        };
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

/// Entries of `vec(G)` whose weights over the lines are proportional: one group's
/// weighted least-squares problems share their regressor up to a scalar per entry
/// (the scalar does not change the solution), so one factorisation serves them all.
///
/// With the measured variance of a multivariable FRF the variances of the entries are
/// often equal (one noise level per experiment) or differ by a constant per entry (a
/// sensor gain), and with uniform weights every entry is in one group; with per-entry
/// spectra the groups are single entries and nothing is shared.
#[derive(Debug, Clone, PartialEq)]
pub struct WeightGroup {
    /// The entries of the group (indices into `vec(G)`), ascending.
    pub entries: Vec<usize>,
    /// The group's weight of each line, scaled so that its largest is 1.
    pub line_weights: Vec<f64>,
    /// Per entry of [`WeightGroup::entries`]: its weights are `scale * line_weights`.
    pub scales: Vec<f64>,
}

/// Groups the entries of the weights `w` (line after line, each line the `m` entries
/// of `vec(G)`, as [`Weighting::weights`] returns them) whose weight vectors over the
/// lines are proportional within a relative `tol` on every line ([`WeightGroup`]).
/// Groups are ordered by their first entry. An entry whose weights are all zero is a
/// group of its own, with scale 1.
pub fn proportional_groups(w: &[f64], m: usize, tol: f64) -> Vec<WeightGroup> {
    if m == 0 {
        return Vec::new();
    }
    let nl = w.len() / m;
    let mut groups: Vec<WeightGroup> = Vec::new();
    for e in 0..m {
        let col = |k: usize| w[k * m + e].max(0.0);
        let top = (0..nl).map(col).fold(0.0f64, f64::max);
        if !(top > 0.0 && top.is_finite()) {
            groups.push(WeightGroup {
                entries: vec![e],
                line_weights: (0..nl)
                    .map(|k| if top.is_finite() { col(k) } else { 0.0 })
                    .collect(),
                scales: vec![1.0],
            });
            continue;
        }
        let found = groups.iter_mut().find(|g| {
            g.line_weights.iter().any(|&x| x > 0.0)
                && (0..nl).all(|k| {
                    (col(k) / top - g.line_weights[k]).abs()
                        <= tol * g.line_weights[k].max(col(k) / top)
                })
        });
        match found {
            Some(g) => {
                g.entries.push(e);
                g.scales.push(top);
            }
            None => groups.push(WeightGroup {
                entries: vec![e],
                line_weights: (0..nl).map(|k| col(k) / top).collect(),
                scales: vec![top],
            }),
        }
    }
    groups
}

#[cfg(test)]
mod group_tests {
    use super::proportional_groups;

    #[test]
    fn proportional_columns_share_a_group_and_others_do_not() {
        // 3 lines, 4 entries: entries 0 and 2 proportional (x3), 1 different, 3 zero
        let m = 4;
        let w = [
            1.0, 1.0, 3.0, 0.0, //
            2.0, 1.0, 6.0, 0.0, //
            4.0, 5.0, 12.0, 0.0,
        ];
        let g = proportional_groups(&w, m, 1e-12);
        assert_eq!(g.len(), 3);
        assert_eq!(g[0].entries, vec![0, 2]);
        assert_eq!(g[0].line_weights, vec![0.25, 0.5, 1.0]);
        assert_eq!(g[0].scales, vec![4.0, 12.0]);
        assert_eq!(g[1].entries, vec![1]);
        assert_eq!(g[2].entries, vec![3]);
        assert_eq!(g[2].line_weights, vec![0.0; 3]);
        // the weights are reproduced
        for gr in &g {
            for (i, &e) in gr.entries.iter().enumerate() {
                for k in 0..3 {
                    assert_eq!(gr.scales[i] * gr.line_weights[k], w[k * m + e]);
                }
            }
        }
    }

    #[test]
    fn a_difference_beyond_the_tolerance_splits_the_group() {
        let w = [1.0, 1.0, 1.0, 1.0 + 1e-6];
        assert_eq!(proportional_groups(&w, 2, 1e-9).len(), 2);
        assert_eq!(proportional_groups(&w, 2, 1e-5).len(), 1);
    }
}
