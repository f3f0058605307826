//! The settings of the ML refiner ([`MlConfig`], [`CovarianceScale`]), with their
//! documented defaults.

use crate::lm::LmSettings;
use crate::varpro::ResidueForm;
use frf_data::{ProgressSink, Weighting};
use serde::{Deserialize, Serialize};

/// How the covariance of the estimates is scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CovarianceScale {
    /// With a measured variance: by `max(1, V / N_dof)`; without: by `V / N_dof` (the
    /// noise scale estimated from the residual). The default.
    #[default]
    Auto,
    /// The inverse Fisher information with the weights as inverse variances, unscaled.
    Fisher,
    /// Always by the cost ratio `V / N_dof`.
    CostRatio,
}

/// Settings of [`MlRefine`](crate::MlRefine), with documented defaults.
#[derive(Debug, Clone)]
pub struct MlConfig {
    /// Weighting of the criterion. Default: [`Weighting::Auto`] (inverse variance, the
    /// ML criterion, when the data carry a variance; eq. (27) of the wafer-stage paper
    /// otherwise, with the noise scale from the residual).
    pub weighting: Weighting,
    /// Parametrisation of the residues. Default: [`ResidueForm::Auto`].
    pub residues: ResidueForm,
    /// Fit a feedthrough `D`. Default: `None`, when the start has a nonzero one.
    pub feedthrough: Option<bool>,
    /// Realizations the variance was estimated from, when known: sets the expected cost
    /// ratio `(R - 1) / (R - 2)` of the cost test. Default: `None` (the variance is
    /// taken as exact).
    pub realizations: Option<usize>,
    /// Real degrees of freedom `d` of each line's variance when it was estimated, when
    /// known: `2 (R - 1)` from `R` realizations, more when it was pooled over
    /// neighbouring lines. Takes the place of `realizations` in the cost test
    /// (`E{V / N_dof} = d / (d - 2)`) and sets the sample-variance factor of the
    /// covariance ([`sample_variance_factor`]). Default: `None` (from `realizations`).
    pub variance_dof: Option<f64>,
    /// Covariance scaling. Default: [`CovarianceScale::Auto`].
    pub covariance: CovarianceScale,
    /// Iterations and tolerances. Default: [`LmSettings::default`].
    pub lm: LmSettings,
    /// Damping given to a start pole pair outside the open left half-plane (a real pole
    /// is reflected). Default: 0.01.
    pub zeta_unstable: f64,
    /// Largest condition number of the column-scaled information matrix before a
    /// parameter is called not identifiable. Default: 1e13.
    pub max_condition: f64,
    /// Modes the refinement may add where the residual shows a resonance the start
    /// missed (only with a measured variance, while the cost test rejects the model at
    /// 1e-3), at least: the limit is the larger of this and `add_modes_fraction` of the
    /// start's pole pairs. Several resonances clear of the model's modes are added in one
    /// refinement (see the messages). Default: 4; 0 keeps the start's structure.
    pub add_modes: usize,
    /// The limit of the added modes relative to the start's pole pairs (rounded up),
    /// where that is more than `add_modes`: a start misses modes in proportion to its
    /// size (the subspace start of a large plant merges close pairs; a random 20 x 20
    /// plant with 50 modes and a rigid body, seed 11, started from 45 pairs, took 5
    /// additions and reached the noise level, where 4 left a triple cluster at 213 to
    /// 217 Hz with two modes at 33 times the noise). Default: 0.2.
    pub add_modes_fraction: f64,
    /// Smallest F statistic (cost explained per added parameter over the noise scale)
    /// for an added mode to be kept. Default: 25.
    pub min_f: f64,
    /// Times an optimum with unstable poles, or with a pole the data do not determine
    /// (the weakest direction of an information matrix beyond `max_condition`), is
    /// answered by dropping those poles (the start had a pole too many: an initialiser
    /// fitting noise at a high order) and refining again from the optimum without them;
    /// the cost test may then add a mode back where the residual calls for one. The
    /// drops are reported in the messages. A start with more than 30 pole pairs may be
    /// answered this way once per ten of them (a random 20 x 20 plant with 50 modes
    /// over 10..500 Hz on 2000 uniform lines, seed 32 of `frfit simulate random-modal`,
    /// crowds ten modes into 10..15 Hz at 0.245 Hz line spacing: five of its subspace
    /// start's poles there crossed into the right half-plane in turn, and the fourth
    /// drop ended the fit with an error). Default: 3; 0 reports the unstable or
    /// unidentifiable optimum as an error.
    pub unstable_drops: usize,
    /// With a measured variance, drop a start real pole that explains less than
    /// `min_f` times the noise per parameter (see [`MlRefine`](crate::MlRefine)'s messages). Default:
    /// true.
    pub prune_real_poles: bool,
    /// With a measured variance, test the integrators of the rigid body at the optimum
    /// (after the structure adaptation, before a held delay is freed and again after):
    /// when they explain less than `min_f` times the noise per parameter with the poles
    /// held (the F test of the mode additions), all of them at once, else the highest
    /// alone, they are dropped and the refinement continued without them, and the test
    /// repeated. An initialiser whose start stood far above the noise level keeps
    /// integrators that took up part of its misfit (random 20 x 20 plants without a
    /// rigid body: two, of full rank); at the noise level they explain nothing.
    /// Default: true.
    pub prune_integrators: bool,
    /// Progress callback.
    pub progress: ProgressSink,
}

impl MlConfig {
    /// The real degrees of freedom of each line's variance: [`MlConfig::variance_dof`],
    /// else `2 (R - 1)` from [`MlConfig::realizations`] (`R >= 2`); `None` when the
    /// variance is taken as exact.
    pub fn variance_dof(&self) -> Option<f64> {
        self.variance_dof.or_else(|| {
            self.realizations
                .filter(|&r| r >= 2)
                .map(|r| 2.0 * (r as f64 - 1.0))
        })
    }
}

/// The factor `(d - 2) / (d - 4)` by which the covariance of an estimate weighted by
/// sample variances of `d` real degrees of freedom exceeds the inverse information
/// formed with those weights and scaled by the cost ratio; 1 for an exact variance
/// (`None`) and where it is not defined (`d <= 4`).
///
/// With the weights `u_k / sigma_k^2`, `u_k = d / chi2_d` independent of the data's
/// noise (the sample mean and the sample variance of Gaussian realizations are
/// independent), the linearised estimate has the covariance
/// `E{u^2} / E{u}^2 F^-1` over many lines (`F` the information with the true
/// variances), while the information with the sample weights is `E{u} F` and the cost
/// ratio `V / N_dof` expects `E{u} = d / (d - 2)`, so their product gives `F^-1`. The
/// ratio `E{u^2} / E{u}^2 = (d - 2) / (d - 4)` is the loss of efficiency of the sample
/// maximum likelihood estimator, `(M - 2) / (M - 3)` for `M` realizations (Pintelon and
/// Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed., on sample
/// variances): 8 / 7 for the usual 10 realizations, 2 for 4, undefined for 3 and
/// fewer (the variance of `u` is then infinite: such variances are pooled over
/// neighbouring lines first). Measured on the wafer stage with 10 realizations before
/// this factor: frequency z RMS 1.075 (refined IV, 100 draws) and 1.061 (ML, 70 draws),
/// against `sqrt(8 / 7) = 1.069`.
pub fn sample_variance_factor(variance_dof: Option<f64>) -> f64 {
    match variance_dof {
        Some(d) if d > 4.0 => (d - 2.0) / (d - 4.0),
        _ => 1.0,
    }
}

impl Default for MlConfig {
    fn default() -> Self {
        Self {
            weighting: Weighting::Auto,
            residues: ResidueForm::Auto,
            feedthrough: None,
            realizations: None,
            variance_dof: None,
            covariance: CovarianceScale::Auto,
            lm: LmSettings::default(),
            zeta_unstable: 0.01,
            max_condition: 1e13,
            add_modes: 4,
            add_modes_fraction: 0.2,
            min_f: 25.0,
            unstable_drops: 3,
            prune_real_poles: true,
            prune_integrators: true,
            progress: ProgressSink::none(),
        }
    }
}
