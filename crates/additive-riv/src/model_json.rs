//! The model file (`MODEL.json`): a versioned, documented JSON form of an
//! [`AdditiveModel`] that `frfit eval` reads back exactly.
//!
//! It holds two views of the same model:
//!
//! - the **modal form** for people and other tools: continuous-time `modes` (natural
//!   frequency, damping, complex residue matrix of the upper pole), the `rigid_body`
//!   (residues of `1/s^k`), the `feedthrough`, and the known factor (`delay_s`, `hold`,
//!   `derivative_order`);
//! - the **submodels** exactly as fitted (scaled coefficients and their scale), from which
//!   the response is reproduced bit for bit.
//!
//! Schema version 1 (`"format": "frfit-additive-model"`, `"version": 1`); fields are
//! documented on [`ModelFile`].

use crate::model::{Submodel, SubmodelKind};
use crate::{AdditiveModel, Domain, KnownFactor, RivError};
use faer::Mat;
use frf_data::uncertainty::PoleUncertainty;
use frf_data::ModelStructure;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The format tag of the model file.
pub const FORMAT: &str = "frfit-additive-model";
/// The schema version written by this crate.
pub const VERSION: u32 = 1;

/// A complex matrix as two real matrices (rows of outputs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComplexMatrix {
    /// Real parts, `ny` rows of `nu`.
    pub re: Vec<Vec<f64>>,
    /// Imaginary parts, `ny` rows of `nu`.
    pub im: Vec<Vec<f64>>,
}

/// One mode of the modal form: `R / (s - p) + conj(R) / (s - conj p)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModeJson {
    /// Natural frequency `|p| / 2 pi`, Hz.
    pub f_hz: f64,
    /// Relative damping `-Re p / |p|`.
    pub zeta: f64,
    /// Residue `R` of the upper pole `p` (continuous time).
    pub residue: ComplexMatrix,
    /// Numerical rank of the residue (singular values above [`RANK_TOL`] of the largest).
    pub rank: usize,
    /// Standard deviation of `f_hz`, Hz, when the refiner computed a covariance
    /// (`--refine ml`: the inverse Fisher information at the optimum, by the delta
    /// method); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f_hz_std: Option<f64>,
    /// Standard deviation of `zeta`, when the refiner computed a covariance; absent
    /// otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zeta_std: Option<f64>,
}

/// The standard deviations of one mode's frequency and damping (from a refiner's
/// covariance), for [`ModelFile::set_uncertainty`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeStd {
    /// Natural frequency, Hz (matches the mode).
    pub f_hz: f64,
    /// Standard deviation of the natural frequency, Hz.
    pub f_hz_std: f64,
    /// Standard deviation of the relative damping.
    pub zeta_std: f64,
}

/// The standard deviations of one dynamics factor's poles and zeros (the upper root of
/// a complex pair), from a refiner's covariance.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FactorStd {
    /// The roots of its denominator.
    pub poles: Vec<PoleUncertainty>,
    /// The roots of its numerator.
    #[serde(default)]
    pub zeros: Vec<PoleUncertainty>,
}

/// The rigid-body part `sum_k R_k / s^k`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RigidBodyJson {
    /// Number of integrators `l`.
    pub integrators: usize,
    /// `residues[k - 1]` is `R_k`, the real coefficient of `1 / s^k`.
    pub residues: Vec<Vec<Vec<f64>>>,
}

/// One submodel exactly as fitted (see [`Submodel`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SubmodelJson {
    /// `rigid_body`, `mode`, `feedthrough`, `suspension` or `general`.
    pub kind: SubmodelKind,
    /// Poles at the origin (`z = 1` in discrete time).
    pub integrators: usize,
    /// Frequency scale `sigma` of the variable `x = s / sigma` (rad/s; 1 in discrete time).
    pub scale: f64,
    /// `a~_1 .. a~_n` of `A(x) = 1 + a~_1 x + ...`.
    pub den: Vec<f64>,
    /// Power of `x` of the first numerator matrix.
    pub num_start: usize,
    /// Numerator matrices `B~_r`, `ny` rows of `nu` each.
    pub num: Vec<Vec<Vec<f64>>>,
    /// Fixed numerator factor `c(x)`, ascending (`[1]` when none).
    #[serde(default = "one_poly")]
    pub num_poly: Vec<f64>,
    /// An exact-hold mode whose numerator shape follows from its poles (then
    /// `num_poly` is recomputed on reading).
    #[serde(default)]
    pub zoh_shape: bool,
    /// The submodel bypasses the known factor (delay, hold): crosstalk.
    #[serde(default)]
    pub bypass_factor: bool,
}

fn one_poly() -> Vec<f64> {
    vec![1.0]
}

/// How the model was obtained.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The estimator, e.g. "additive RIV, Algorithm 1 (CMIF init, inverse variance)".
    pub estimator: String,
    /// The data file, when known.
    pub data: Option<String>,
    /// Weighting of the criterion.
    pub weighting: String,
    /// Iterations run.
    pub iterations: usize,
    /// Why the iterations stopped.
    pub convergence: String,
    /// Final cost (8).
    pub cost: Option<f64>,
    /// Version of frfit.
    pub frfit_version: String,
    /// Free-form notes (messages of the fit).
    pub notes: Vec<String>,
    /// The estimator chain that made the model (`["cmif", "riv"]`), when it came from
    /// one.
    #[serde(default)]
    pub chain: Vec<String>,
    /// Each link's report (iterations, convergence, cost history, timings, notes and the
    /// method's own details), in the order of `chain`.
    #[serde(default)]
    pub links: Vec<frf_data::LinkReport>,
    /// For a model reduced by balanced truncation (`frfit reduce`): every Hankel singular
    /// value of the stable part of the model it was reduced from, descending. Absent
    /// otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hankel_singular_values: Option<Vec<f64>>,
    /// For a reduced model: the a-priori bound `2 sum(discarded Hankel singular values)`
    /// on the H-infinity norm of the difference to the model it was reduced from (of the
    /// rational part; the known factors are the same). Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_bound: Option<f64>,
}

/// The model file, schema version 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Always `"frfit-additive-model"`.
    pub format: String,
    /// Schema version (1).
    pub version: u32,
    /// Outputs.
    pub ny: usize,
    /// Inputs.
    pub nu: usize,
    /// Units of the modelled FRF, when known.
    pub units: Option<String>,
    /// Frequency band of the fit, Hz.
    pub band_hz: Option<[f64; 2]>,
    /// Time variable of the submodels (`continuous` or `zoh_discrete` with `ts`).
    pub domain: Domain,
    /// Delay `tau` of the known factor `exp(-j w tau)`, seconds.
    pub delay_s: f64,
    /// Whether the delay was a fitted parameter.
    pub delay_fitted: bool,
    /// Standard deviation of a fitted `delay_s`, seconds, when the refiner computed a
    /// covariance; absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_s_std: Option<f64>,
    /// The hold: `"zoh:FS"` (exact, in the domain), `"sinc:FS"` (amplitude factor) or
    /// `"none"`.
    pub hold: String,
    /// `k` of the factor `(j w)^k` (0 displacement, 1 velocity, 2 accelerance).
    pub derivative_order: u32,
    /// Continuous-time modes (the hold, if any, mapped back exactly).
    pub modes: Vec<ModeJson>,
    /// Rigid-body part, when present.
    pub rigid_body: Option<RigidBodyJson>,
    /// Real poles other than modes (rare: overdamped submodels).
    pub real_poles: Vec<(f64, Vec<Vec<f64>>)>,
    /// Feedthrough `D`, when non-zero.
    pub feedthrough: Option<Vec<Vec<f64>>>,
    /// Minimal number of states of the real realisation (residues at rank tolerance
    /// [`RANK_TOL`]).
    pub order: usize,
    /// The submodels exactly as fitted.
    pub submodels: Vec<SubmodelJson>,
    /// Fitted dynamics factors of input columns or output rows (not part of the modal
    /// form, like the delay): `1 / (1 + a~_1 s/scale + ...)`.
    #[serde(default)]
    pub dynamics: Vec<crate::model::DynamicsFactor>,
    /// Per entry of `dynamics`, in its order, the standard deviations of the factor's
    /// poles and zeros when the refiner computed a covariance; absent otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dynamics_std: Vec<FactorStd>,
    /// How the model was obtained.
    pub provenance: Provenance,
}

fn rows(m: &Mat<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

fn from_rows(r: &[Vec<f64>], ny: usize, nu: usize, what: &str) -> Result<Mat<f64>, RivError> {
    if r.len() != ny || r.iter().any(|row| row.len() != nu) {
        return Err(RivError::Structure(format!("{what} must be {ny}x{nu}")));
    }
    if r.iter().flatten().any(|v| !v.is_finite()) {
        return Err(RivError::Structure(format!(
            "{what} holds a non-finite value"
        )));
    }
    Ok(Mat::from_fn(ny, nu, |i, j| r[i][j]))
}

/// Relative rank tolerance of the `rank` and `order` fields: singular values of a residue
/// below 3 % of its largest are not resolved by measured FRFs (on the wafer stage the
/// second singular value of a fitted rank-one residue is 0.2 % to 1.7 % of the first,
/// from noise and the unmodelled hold; a genuinely rank-2 residue of a repeated mode
/// is far above). `order` is then the minimal real state dimension, 40 for the wafer
/// stage (3 rigid-body directions x 2 + 17 rank-one modes x 2).
pub const RANK_TOL: f64 = 0.03;

impl ModelFile {
    /// Builds the file from a model and its provenance.
    pub fn from_model(
        model: &AdditiveModel,
        units: Option<String>,
        band_hz: Option<(f64, f64)>,
        provenance: Provenance,
    ) -> Result<Self, RivError> {
        let mm = model.to_modal_model()?;
        let modes = mm
            .pairs
            .iter()
            .map(|p| {
                let sv = p.residue.singular_values().unwrap_or_default();
                let top = sv.first().copied().unwrap_or(0.0);
                ModeJson {
                    f_hz: p.f_hz(),
                    zeta: p.zeta(),
                    residue: ComplexMatrix {
                        re: (0..mm.ny)
                            .map(|i| (0..mm.nu).map(|j| p.residue[(i, j)].re).collect())
                            .collect(),
                        im: (0..mm.ny)
                            .map(|i| (0..mm.nu).map(|j| p.residue[(i, j)].im).collect())
                            .collect(),
                    },
                    rank: sv.iter().filter(|&&s| s > RANK_TOL * top).count(),
                    f_hz_std: None,
                    zeta_std: None,
                }
            })
            .collect();
        let rigid_body = (!mm.rigid.is_empty()).then(|| RigidBodyJson {
            integrators: mm.rigid.len(),
            residues: mm.rigid.iter().map(rows).collect(),
        });
        let has_d = (0..mm.ny).any(|i| (0..mm.nu).any(|j| mm.feedthrough[(i, j)] != 0.0));
        let hold = match (model.domain(), model.factor.sinc_hold_fs) {
            (Domain::ZohDiscrete { ts }, _) => format!("zoh:{}", 1.0 / ts),
            (_, Some(fs)) => format!("sinc:{fs}"),
            _ => "none".into(),
        };
        Ok(Self {
            format: FORMAT.into(),
            version: VERSION,
            ny: model.ny(),
            nu: model.nu(),
            units,
            band_hz: band_hz.map(|(a, b)| [a, b]),
            domain: model.domain(),
            delay_s: model.factor.delay_s,
            delay_fitted: model.factor.fit_delay,
            delay_s_std: None,
            hold,
            derivative_order: model.factor.derivative_order,
            modes,
            rigid_body,
            real_poles: mm
                .real_poles
                .iter()
                .map(|r| (r.pole, rows(&r.residue)))
                .collect(),
            feedthrough: has_d.then(|| rows(&mm.feedthrough)),
            order: mm.order(RANK_TOL),
            submodels: model
                .submodels
                .iter()
                .map(|s| SubmodelJson {
                    kind: s.kind,
                    integrators: s.integrators,
                    scale: s.scale,
                    den: s.den.clone(),
                    num_start: s.num_start,
                    num: s.num.iter().map(rows).collect(),
                    num_poly: s.num_poly.clone(),
                    zoh_shape: s.zoh_shape,
                    bypass_factor: s.bypass_factor,
                })
                .collect(),
            dynamics: model.dynamics.clone(),
            dynamics_std: Vec::new(),
            provenance,
        })
    }

    /// Rebuilds the exact model from the `submodels`, `domain` and known factor.
    pub fn to_model(&self) -> Result<AdditiveModel, RivError> {
        if self.format != FORMAT {
            return Err(RivError::Structure(format!(
                "not an frfit model file (format `{}`, expected `{FORMAT}`)",
                self.format
            )));
        }
        if self.version != VERSION {
            return Err(RivError::Structure(format!(
                "model file version {} is not supported (this frfit reads version {VERSION})",
                self.version
            )));
        }
        let sinc = self
            .hold
            .strip_prefix("sinc:")
            .map(|f| f.parse::<f64>())
            .transpose()
            .map_err(|_| {
                RivError::Structure(format!(
                    "hold `{}` does not parse (expected sinc:FS)",
                    self.hold
                ))
            })?;
        let mut m =
            AdditiveModel::new(self.ny, self.nu, self.domain)?.with_factor(KnownFactor {
                delay_s: self.delay_s,
                fit_delay: self.delay_fitted,
                derivative_order: self.derivative_order,
                sinc_hold_fs: sinc,
            })?;
        for d in &self.dynamics {
            m.push_dynamics(d.clone())?;
        }
        for (i, s) in self.submodels.iter().enumerate() {
            let num = s
                .num
                .iter()
                .map(|r| from_rows(r, self.ny, self.nu, &format!("submodels[{i}].num")))
                .collect::<Result<Vec<_>, _>>()?;
            if s.den.iter().any(|v| !v.is_finite()) {
                return Err(RivError::Structure(format!(
                    "submodels[{i}].den holds a non-finite value"
                )));
            }
            m.push_submodel(Submodel {
                kind: s.kind,
                integrators: s.integrators,
                den: s.den.clone(),
                num_start: s.num_start,
                num,
                scale: s.scale,
                num_poly: s.num_poly.clone(),
                zoh_shape: s.zoh_shape,
                bypass_factor: s.bypass_factor,
            })?;
        }
        self.check_summary(&m)?;
        Ok(m)
    }

    /// The derived fields (`modes`, `rigid_body`) must be those of the model the
    /// `submodels` rebuild: a file edited by hand or damaged there would otherwise be read
    /// as something other than what it shows. The error names the field.
    fn check_summary(&self, m: &AdditiveModel) -> Result<(), RivError> {
        let mm = m.to_modal_model()?;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-300);
        let mismatch = |field: String, shown: f64, rebuilt: f64| {
            RivError::Structure(format!(
                "{field} is {shown} but the submodels, from which the model is rebuilt exactly, give {rebuilt}: the file was edited or damaged (`modes` is a summary: edit `submodels` or fit again)"
            ))
        };
        if self.modes.len() != mm.pairs.len() {
            return Err(RivError::Structure(format!(
                "modes lists {} modes but the submodels hold {}: the file was edited or damaged",
                self.modes.len(),
                mm.pairs.len()
            )));
        }
        for (i, (shown, p)) in self.modes.iter().zip(&mm.pairs).enumerate() {
            if !close(shown.f_hz, p.f_hz()) {
                return Err(mismatch(format!("modes[{i}].f_hz"), shown.f_hz, p.f_hz()));
            }
            if !close(shown.zeta, p.zeta()) {
                return Err(mismatch(format!("modes[{i}].zeta"), shown.zeta, p.zeta()));
            }
            let (re, im) = (&shown.residue.re, &shown.residue.im);
            let shape_ok =
                |r: &Vec<Vec<f64>>| r.len() == self.ny && r.iter().all(|row| row.len() == self.nu);
            if !(shape_ok(re) && shape_ok(im)) {
                return Err(RivError::Structure(format!(
                    "modes[{i}].residue is not {}x{} (ny x nu of the file)",
                    self.ny, self.nu
                )));
            }
        }
        self.check_uncertainty()?;
        let integrators = self.rigid_body.as_ref().map_or(0, |r| r.integrators);
        if integrators != mm.rigid.len() {
            return Err(mismatch(
                "rigid_body.integrators".into(),
                integrators as f64,
                mm.rigid.len() as f64,
            ));
        }
        Ok(())
    }

    /// The standard deviations are not derivable from the submodels: they are checked
    /// for what they can be checked (present in pairs, finite, non-negative, a delay
    /// standard deviation only for a fitted delay); the error names the field.
    fn check_uncertainty(&self) -> Result<(), RivError> {
        let check = |field: String, v: Option<f64>| match v {
            Some(x) if !(x.is_finite() && x >= 0.0) => Err(RivError::Structure(format!(
                "{field} is {x}: a standard deviation must be finite and non-negative"
            ))),
            _ => Ok(()),
        };
        for (i, m) in self.modes.iter().enumerate() {
            check(format!("modes[{i}].f_hz_std"), m.f_hz_std)?;
            check(format!("modes[{i}].zeta_std"), m.zeta_std)?;
            if m.f_hz_std.is_some() != m.zeta_std.is_some() {
                let (has, lacks) = if m.f_hz_std.is_some() {
                    ("f_hz_std", "zeta_std")
                } else {
                    ("zeta_std", "f_hz_std")
                };
                return Err(RivError::Structure(format!(
                    "modes[{i}] has {has} but no {lacks}: both come from one covariance"
                )));
            }
        }
        check("delay_s_std".into(), self.delay_s_std)?;
        if !self.dynamics_std.is_empty() && self.dynamics_std.len() != self.dynamics.len() {
            return Err(RivError::Structure(format!(
                "dynamics_std lists {} factors but dynamics holds {}",
                self.dynamics_std.len(),
                self.dynamics.len()
            )));
        }
        for (k, f) in self.dynamics_std.iter().enumerate() {
            for (kind, roots) in [("poles", &f.poles), ("zeros", &f.zeros)] {
                for (r, root) in roots.iter().enumerate() {
                    check(
                        format!("dynamics_std[{k}].{kind}[{r}].f_hz_std"),
                        Some(root.f_hz_std),
                    )?;
                    check(
                        format!("dynamics_std[{k}].{kind}[{r}].zeta_std"),
                        Some(root.zeta_std),
                    )?;
                }
            }
        }
        if self.delay_s_std.is_some() && !self.delay_fitted {
            return Err(RivError::Structure(
                "delay_s_std is given but delay_fitted is false: only a fitted delay has a standard deviation".into(),
            ));
        }
        Ok(())
    }

    /// Writes the standard deviations of a refiner's covariance into the modal form:
    /// each mode of the file takes `f_hz_std` and `zeta_std` of the entry of `modes`
    /// nearest in frequency (within 1e-6 relative: the same model), and `delay_s_std`
    /// is set when the delay was fitted. An error names a mode without a match, a
    /// standard deviation that is not finite and non-negative, or a delay standard
    /// deviation for a delay that was not fitted; the file is unchanged then.
    pub fn set_uncertainty(
        &mut self,
        modes: &[ModeStd],
        delay_s_std: Option<f64>,
    ) -> Result<(), RivError> {
        let mut next = self.clone();
        for (i, m) in next.modes.iter_mut().enumerate() {
            let near = modes
                .iter()
                .filter(|u| (u.f_hz - m.f_hz).abs() <= 1e-6 * m.f_hz.abs())
                .min_by(|a, b| (a.f_hz - m.f_hz).abs().total_cmp(&(b.f_hz - m.f_hz).abs()))
                .ok_or_else(|| {
                    RivError::Structure(format!(
                        "modes[{i}] at {} Hz has no standard deviation in the covariance given (its modes: {:?} Hz)",
                        m.f_hz,
                        modes.iter().map(|u| u.f_hz).collect::<Vec<_>>()
                    ))
                })?;
            m.f_hz_std = Some(near.f_hz_std);
            m.zeta_std = Some(near.zeta_std);
        }
        next.delay_s_std = delay_s_std;
        next.check_uncertainty()?;
        *self = next;
        Ok(())
    }

    /// Writes the standard deviations of the dynamics factors' poles and zeros, one
    /// entry per factor of `dynamics` in its order. An error names a count that does
    /// not match or a standard deviation that is not finite and non-negative; the file
    /// is unchanged then.
    pub fn set_factor_uncertainty(&mut self, factors: Vec<FactorStd>) -> Result<(), RivError> {
        let mut next = self.clone();
        next.dynamics_std = factors;
        next.check_uncertainty()?;
        *self = next;
        Ok(())
    }

    /// Reads and checks a model file.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, RivError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| RivError::ModelFile {
            path: path.display().to_string(),
            why: e.to_string(),
        })?;
        let f: ModelFile = serde_json::from_str(&text).map_err(|e| RivError::ModelFile {
            path: path.display().to_string(),
            why: format!("line {} column {}: {e}", e.line(), e.column()),
        })?;
        f.to_model().map_err(|e| RivError::ModelFile {
            path: path.display().to_string(),
            why: e.to_string(),
        })?;
        Ok(f)
    }

    /// Writes the file (pretty-printed JSON).
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), RivError> {
        let path = path.as_ref();
        let text = serde_json::to_string_pretty(self).map_err(|e| RivError::ModelFile {
            path: path.display().to_string(),
            why: e.to_string(),
        })?;
        std::fs::write(path, text).map_err(|e| RivError::ModelFile {
            path: path.display().to_string(),
            why: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    #[test]
    fn round_trip_reproduces_the_response() {
        for domain in [Domain::Continuous, Domain::ZohDiscrete { ts: 1e-4 }] {
            let mut m = AdditiveModel::new(2, 3, domain).unwrap();
            m.push_rigid_body(2, 300.0).unwrap();
            m.push_mode(150.0, 0.01, false).unwrap();
            m.push_mode(900.0, 0.02, false).unwrap();
            m.push_feedthrough().unwrap();
            let mut v = 0.1;
            for s in &mut m.submodels {
                for b in &mut s.num {
                    for j in 0..3 {
                        for i in 0..2 {
                            v = (v * 7.3 + 0.37) % 1.0 - 0.5;
                            b[(i, j)] = v;
                        }
                    }
                }
            }
            let m = m
                .with_factor(KnownFactor {
                    delay_s: 1e-4,
                    fit_delay: true,
                    ..Default::default()
                })
                .unwrap();
            let f = ModelFile::from_model(
                &m,
                Some("m/N".into()),
                Some((20.0, 2000.0)),
                Provenance::default(),
            )
            .unwrap();
            let text = serde_json::to_string(&f).unwrap();
            let back: ModelFile = serde_json::from_str(&text).unwrap();
            let m2 = back.to_model().unwrap();
            let w: Vec<f64> = (1..100).map(|k| TAU * 20.0 * k as f64).collect();
            let (a, b) = (m.response_at(&w), m2.response_at(&w));
            assert!(
                a.values.iter().zip(&b.values).all(|(x, y)| x == y),
                "response changed in the round trip"
            );
            assert_eq!(f.modes.len(), 2);
            assert!(f.rigid_body.is_some());
        }
    }

    #[test]
    fn wrong_format_and_version_are_rejected() {
        let m = {
            let mut m = AdditiveModel::new(1, 1, Domain::Continuous).unwrap();
            m.push_mode(10.0, 0.1, false).unwrap();
            m
        };
        let mut f = ModelFile::from_model(&m, None, None, Provenance::default()).unwrap();
        f.version = 99;
        assert!(f.to_model().unwrap_err().to_string().contains("version 99"));
        f.version = VERSION;
        f.format = "x".into();
        assert!(f.to_model().is_err());
    }

    /// Valid JSON, wrong content in the derived fields: the error names the field.
    #[test]
    fn edited_summary_fields_are_named() {
        let mut m = AdditiveModel::new(2, 2, Domain::Continuous).unwrap();
        m.push_rigid_body(2, 30.0).unwrap();
        m.push_mode(10.0, 0.1, false).unwrap();
        m.push_mode(40.0, 0.02, false).unwrap();
        for s in &mut m.submodels {
            for b in &mut s.num {
                for j in 0..2 {
                    for i in 0..2 {
                        b[(i, j)] = 1.0 + (i + 2 * j) as f64;
                    }
                }
            }
        }
        let f = ModelFile::from_model(&m, None, None, Provenance::default()).unwrap();
        f.to_model().expect("the file as written reads back");
        let text = serde_json::to_string(&f).unwrap();
        let edited = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
            edit(&mut v);
            let g: ModelFile = serde_json::from_value(v).unwrap();
            g.to_model().unwrap_err().to_string()
        };
        let e = edited(&|v| v["modes"][1]["zeta"] = serde_json::json!(-0.02));
        assert!(e.contains("modes[1].zeta is -0.02"), "{e}");
        let e = edited(&|v| v["modes"][0]["f_hz"] = serde_json::json!(11.0));
        assert!(e.contains("modes[0].f_hz is 11"), "{e}");
        let e = edited(&|v| {
            v["modes"].as_array_mut().unwrap().pop();
        });
        assert!(
            e.contains("modes lists 1 modes but the submodels hold 2"),
            "{e}"
        );
        let e = edited(&|v| v["modes"][0]["residue"]["re"] = serde_json::json!([[1.0, 2.0]]));
        assert!(e.contains("modes[0].residue is not 2x2"), "{e}");
        let e = edited(&|v| v["rigid_body"]["integrators"] = serde_json::json!(1));
        assert!(e.contains("rigid_body.integrators"), "{e}");
    }

    /// A link's own report is written with its kind and reads back as its type; a file
    /// whose report carries no kind (written before the tag) still opens, without it.
    #[test]
    fn link_reports_read_back_as_their_type() {
        let mut m = AdditiveModel::new(1, 1, Domain::Continuous).unwrap();
        m.push_mode(10.0, 0.1, false).unwrap();
        let report = crate::chain::RivReport {
            weighting: "inverse variance".into(),
            ..Default::default()
        };
        let link = frf_data::LinkReport {
            link: "riv".into(),
            estimator: "refined IV".into(),
            iterations: 3,
            convergence: frf_data::Convergence::Direct,
            cost_history: vec![2.0, 1.0, 1.0],
            timings: vec![],
            messages: vec![],
            details: Some(std::sync::Arc::new(report)),
        };
        let prov = Provenance {
            chain: vec!["riv".into()],
            links: vec![link],
            ..Default::default()
        };
        let f = ModelFile::from_model(&m, None, None, prov).unwrap();
        let text = serde_json::to_string(&f).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let details = &v["provenance"]["links"][0]["details"];
        assert_eq!(details["report"], "riv", "{details}");
        assert_eq!(details["weighting"], "inverse variance", "{details}");
        let back: ModelFile = serde_json::from_str(&text).unwrap();
        assert_eq!(back.provenance, f.provenance);
        let r = back.provenance.links[0]
            .details_as::<crate::chain::RivReport>()
            .expect("the riv report reads back as RivReport");
        assert_eq!(r.weighting, "inverse variance");
        assert!(back.provenance.links[0]
            .details_as::<crate::chain::CmifInitReport>()
            .is_none());
        let mut old = v.clone();
        old["provenance"]["links"][0]["details"]
            .as_object_mut()
            .unwrap()
            .remove("report");
        let back: ModelFile = serde_json::from_value(old).unwrap();
        assert!(back.provenance.links[0].details.is_none());
        assert_eq!(back.provenance.links[0].iterations, 3);
        back.to_model().expect("an old file still opens");
    }

    /// The dynamics factors' standard deviations: one entry per factor, checked, kept
    /// through the file.
    #[test]
    fn factor_standard_deviations_are_checked_and_kept() {
        let mut m = AdditiveModel::new(2, 2, Domain::Continuous).unwrap();
        m.push_mode(10.0, 0.1, false).unwrap();
        m.push_dynamics(crate::model::DynamicsFactor::first_order(
            crate::model::FactorTarget::Input(1),
            800.0,
        ))
        .unwrap();
        let mut f = ModelFile::from_model(&m, None, None, Provenance::default()).unwrap();
        let lag = FactorStd {
            poles: vec![PoleUncertainty {
                f_hz: 800.0,
                f_hz_std: 0.003,
                zeta: 1.0,
                zeta_std: 0.0,
            }],
            zeros: vec![],
        };
        let e = f
            .set_factor_uncertainty(vec![lag.clone(), lag.clone()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("dynamics_std lists 2 factors but dynamics holds 1"),
            "{e}"
        );
        let mut bad = lag.clone();
        bad.poles[0].f_hz_std = -1.0;
        let e = f.set_factor_uncertainty(vec![bad]).unwrap_err().to_string();
        assert!(e.contains("dynamics_std[0].poles[0].f_hz_std is -1"), "{e}");
        assert!(
            f.dynamics_std.is_empty(),
            "the file is unchanged after an error"
        );
        f.set_factor_uncertainty(vec![lag.clone()]).unwrap();
        let text = serde_json::to_string(&f).unwrap();
        let back: ModelFile = serde_json::from_str(&text).unwrap();
        assert_eq!(back.dynamics_std, vec![lag]);
        back.to_model().expect("reads back");
        // a file without them reads as before
        let plain = ModelFile::from_model(&m, None, None, Provenance::default()).unwrap();
        let text = serde_json::to_string(&plain).unwrap();
        assert!(!text.contains("dynamics_std"));
    }

    fn two_mode_file(fit_delay: bool) -> ModelFile {
        let mut m = AdditiveModel::new(2, 1, Domain::Continuous).unwrap();
        m.push_mode(10.0, 0.1, false).unwrap();
        m.push_mode(40.0, 0.02, false).unwrap();
        for s in &mut m.submodels {
            for b in &mut s.num {
                b[(0, 0)] = 1.0;
                b[(1, 0)] = -0.5;
            }
        }
        let m = m
            .with_factor(KnownFactor {
                delay_s: 2e-4,
                fit_delay,
                ..Default::default()
            })
            .unwrap();
        ModelFile::from_model(&m, None, None, Provenance::default()).unwrap()
    }

    /// Without a covariance the fields are absent from the text; an older file without
    /// them reads; with one they are written, read back and checked.
    #[test]
    fn standard_deviations_are_optional_and_round_trip() {
        let mut f = two_mode_file(true);
        let text = serde_json::to_string(&f).unwrap();
        assert!(!text.contains("f_hz_std") && !text.contains("delay_s_std"));
        let old: ModelFile = serde_json::from_str(&text).unwrap();
        old.to_model()
            .expect("a file without standard deviations reads");
        assert!(old.modes.iter().all(|m| m.f_hz_std.is_none()));
        let stds = [
            ModeStd {
                f_hz: f.modes[1].f_hz * (1.0 + 1e-9),
                f_hz_std: 0.02,
                zeta_std: 3e-4,
            },
            ModeStd {
                f_hz: f.modes[0].f_hz,
                f_hz_std: 0.01,
                zeta_std: 1e-3,
            },
        ];
        f.set_uncertainty(&stds, Some(1e-7)).unwrap();
        assert_eq!(
            (f.modes[0].f_hz_std, f.modes[0].zeta_std),
            (Some(0.01), Some(1e-3))
        );
        assert_eq!(
            (f.modes[1].f_hz_std, f.modes[1].zeta_std),
            (Some(0.02), Some(3e-4))
        );
        let text = serde_json::to_string(&f).unwrap();
        let back: ModelFile = serde_json::from_str(&text).unwrap();
        back.to_model().unwrap();
        assert_eq!(back, f);
        // a mode without a match, or a delay that was not fitted: errors, file unchanged
        let before = f.clone();
        let e = f.set_uncertainty(&stds[1..], None).unwrap_err().to_string();
        assert!(e.contains("modes[1]"), "{e}");
        assert_eq!(f, before);
        let mut g = two_mode_file(false);
        let e = g
            .set_uncertainty(&stds, Some(1e-7))
            .unwrap_err()
            .to_string();
        assert!(e.contains("delay_s_std"), "{e}");
        let e = g
            .set_uncertainty(
                &[
                    stds[0],
                    ModeStd {
                        zeta_std: f64::NAN,
                        ..stds[1]
                    },
                ],
                None,
            )
            .unwrap_err()
            .to_string();
        assert!(e.contains("modes[0].zeta_std"), "{e}");
    }

    /// Edited standard deviations: the error names the field.
    #[test]
    fn edited_standard_deviations_are_named() {
        let mut f = two_mode_file(true);
        let stds: Vec<ModeStd> = f
            .modes
            .iter()
            .map(|m| ModeStd {
                f_hz: m.f_hz,
                f_hz_std: 0.01,
                zeta_std: 1e-3,
            })
            .collect();
        f.set_uncertainty(&stds, Some(1e-7)).unwrap();
        let text = serde_json::to_string(&f).unwrap();
        let edited = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
            edit(&mut v);
            let g: ModelFile = serde_json::from_value(v).unwrap();
            g.to_model().unwrap_err().to_string()
        };
        let e = edited(&|v| v["modes"][1]["f_hz_std"] = serde_json::json!(-0.5));
        assert!(e.contains("modes[1].f_hz_std is -0.5"), "{e}");
        let e = edited(&|v| {
            v["modes"][0].as_object_mut().unwrap().remove("zeta_std");
        });
        assert!(e.contains("modes[0] has f_hz_std but no zeta_std"), "{e}");
        let e = edited(&|v| v["delay_s_std"] = serde_json::json!(-1e-6));
        assert!(e.contains("delay_s_std is -0.000001"), "{e}");
        let e = edited(&|v| v["delay_fitted"] = serde_json::json!(false));
        assert!(e.contains("delay_fitted is false"), "{e}");
    }
}
