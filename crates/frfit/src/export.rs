//! The fitted model as a real state space for controller design (`frfit export`).
//!
//! The rational part of the model currency ([`FrfModel`]) is realized in real modal
//! block form ([`realize::ModalModel::to_state_space`]: rigid-body integrator chains
//! first, one `2 x 2` block per retained singular value of each mode's residue, then the
//! real poles), and the known factors are written beside it as what they are:
//!
//! `P(j w) = D(w) .* ( (j w)^k exp(-j w tau) H(w) + X )`
//!
//! with `H(w) = C (j w I - A)^-1 B + D` for a continuous model, or, when the model was
//! fitted with the exact zero-order hold, `H(w) = Cd (z I - Ad)^-1 Bd + Dd` at
//! `z = exp(j w Ts)` (the exact ZOH equivalent, Van Loan's block exponential), `tau`
//! the delay beyond the hold, `k` the derivative order of the data (0 displacement,
//! 1 velocity, 2 accelerance), `X` a crosstalk that bypasses the delay and `D(w)` the
//! fitted actuator/sensor dynamics factors. MATLAB's `ss(A, B, C, D)` (with
//! `'OutputDelay'` or `'InputDelay'` = `delay_s`) and python-control's `StateSpace` take
//! the matrices as they are.
//!
//! A discrete equivalent is written on request for a continuous model too (`--discrete
//! FS_HZ`: exact ZOH at that rate, the delay then also stated in samples). A Pade
//! approximation of the delay is not written: the delay is given exactly.

use crate::FrfitError;
use frf_data::io::mat5::{mat5_bytes, MatWrite};
use realize::{DynamicsFactor, FrfModel, Hold, StateSpace};
use serde::{Deserialize, Serialize};

/// Format name of the exported JSON.
pub const FORMAT: &str = "frfit-state-space";
/// Format version.
pub const VERSION: u32 = 1;

/// Real matrices `A, B, C, D`, row-major (`a[i][j]` is row `i`, column `j`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Matrices {
    /// State matrix (`n x n`).
    pub a: Vec<Vec<f64>>,
    /// Input matrix (`n x nu`).
    pub b: Vec<Vec<f64>>,
    /// Output matrix (`ny x n`).
    pub c: Vec<Vec<f64>>,
    /// Feedthrough (`ny x nu`).
    pub d: Vec<Vec<f64>>,
}

/// The rows of `m`.
fn rows(m: &faer::Mat<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

impl Matrices {
    fn of(ss: &StateSpace) -> Self {
        Self {
            a: rows(&ss.a),
            b: rows(&ss.b),
            c: rows(&ss.c),
            d: rows(&ss.d),
        }
    }
}

/// The exact zero-order-hold equivalent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Discrete {
    /// Sample time, seconds.
    pub ts_s: f64,
    /// `Ad, Bd, Cd, Dd`.
    pub matrices: Matrices,
    /// Why it is here: the model's own hold (`"fitted with the exact zero-order hold"`)
    /// or a request.
    pub origin: String,
    /// The delay beyond the hold in samples (`delay_s / ts_s`; not rounded).
    pub delay_samples: f64,
}

/// The factors that multiply (or bypass) the rational part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Factors {
    /// `tau`, seconds (beyond the hold when the hold is exact ZOH).
    pub delay_s: f64,
    /// `k` of `(j w)^k`.
    pub derivative_order: u32,
    /// The hold the model was fitted with (`none`, `zoh:FS`, `sinc:FS`).
    pub hold: String,
    /// `X`, `ny x nu` row-major, when the model has a crosstalk that bypasses the delay.
    pub crosstalk: Option<Vec<Vec<f64>>>,
    /// `D(w)`: the fitted dynamics factors (`B(s/scale) / A(s/scale)`, see
    /// [`DynamicsFactor`]).
    pub dynamics: Vec<DynamicsFactor>,
}

/// The exported model (`frfit-state-space` version 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateSpaceExport {
    /// [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// Outputs.
    pub ny: usize,
    /// Inputs.
    pub nu: usize,
    /// States of the continuous realization.
    pub n_states: usize,
    /// The response formula the matrices and factors make (see the module documentation).
    pub response: String,
    /// The continuous-time realization of the rational part.
    pub continuous: Matrices,
    /// The exact ZOH equivalent (the model's hold, or `--discrete`).
    pub discrete: Option<Discrete>,
    /// The factors stated beside the matrices.
    pub factors: Factors,
    /// Units of the model (from the model file), when known.
    pub units: Option<String>,
    /// The relative rank tolerance of the residues (0: working precision).
    pub rank_tol: f64,
    /// The flexible modes with their standard deviations when the model file holds them
    /// (from the refiner's covariance, `--refine ml`), so that a robust controller
    /// design reads the modal parameters' uncertainty beside the matrices; empty when
    /// the export did not come from a model file.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub modes: Vec<ExportedMode>,
    /// Standard deviation of the fitted delay, seconds, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_s_std: Option<f64>,
    /// Per factor of `factors.dynamics`, in its order, its poles and zeros with their
    /// standard deviations, when the model file holds them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dynamics_std: Vec<additive_riv::FactorStd>,
}

/// A flexible mode of the exported model and its standard deviations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExportedMode {
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Relative damping.
    pub zeta: f64,
    /// Standard deviation of `f_hz`, Hz, when the refiner computed a covariance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f_hz_std: Option<f64>,
    /// Standard deviation of `zeta`, likewise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zeta_std: Option<f64>,
}

/// The state space of `model` (see the module documentation); `discrete_fs_hz` asks for
/// the exact ZOH equivalent at that rate when the model has no exact hold of its own.
/// Each residue keeps the singular values above `rank_tol` times its largest (`0`: every
/// direction above working precision, so that the realization reproduces the model
/// exactly; a fitted rank-one mode then may take 4 states instead of 2).
pub fn export_state_space(
    model: &FrfModel,
    discrete_fs_hz: Option<f64>,
    rank_tol: f64,
    units: Option<String>,
) -> Result<StateSpaceExport, FrfitError> {
    if !(rank_tol.is_finite() && (0.0..1.0).contains(&rank_tol)) {
        return Err(FrfitError::argument(
            "--rank-tol",
            rank_tol,
            "the relative rank tolerance must be in [0, 1)",
        ));
    }
    let realize_err = |e: realize::RealizeError| FrfitError::Fit {
        what: "state-space realization of the model".into(),
        why: e.to_string(),
    };
    model.validate().map_err(realize_err)?;
    let ss = model.modal.to_state_space(rank_tol).map_err(realize_err)?;
    let f = &model.factors;
    let (fs, origin) = match (f.hold, discrete_fs_hz) {
        (Hold::Zoh { fs_hz }, _) => (
            Some(fs_hz),
            "the model was fitted with the exact zero-order hold: this is its rational part",
        ),
        (_, Some(fs_hz)) => {
            if !(fs_hz.is_finite() && fs_hz > 0.0) {
                return Err(FrfitError::argument(
                    "--discrete",
                    fs_hz,
                    "the sample rate must be a positive number of Hz",
                ));
            }
            (
                Some(fs_hz),
                "requested: the exact zero-order-hold equivalent of the continuous part",
            )
        }
        _ => (None, ""),
    };
    let discrete = match fs {
        Some(fs_hz) => {
            let ts = 1.0 / fs_hz;
            let d = ss.discretize_zoh(ts).map_err(realize_err)?;
            Some(Discrete {
                ts_s: ts,
                matrices: Matrices::of(&d),
                origin: origin.into(),
                delay_samples: f.delay_s / ts,
            })
        }
        None => None,
    };
    let h = if matches!(f.hold, Hold::Zoh { .. }) {
        "Cd (z I - Ad)^-1 Bd + Dd at z = exp(j w Ts) (discrete)"
    } else {
        "C (j w I - A)^-1 B + D (continuous)"
    };
    let mut response = format!(
        "P(j w) = (j w)^{} exp(-j w {:.6e}) [{h}]",
        f.derivative_order, f.delay_s
    );
    if let Hold::Sinc { fs_hz } = f.hold {
        response.push_str(&format!(" sinc(w / (2 {fs_hz}))"));
    }
    if f.crosstalk.is_some() {
        response.push_str(" + X (crosstalk)");
    }
    if !f.dynamics.is_empty() {
        response = format!("dynamics factors .* ({response})");
    }
    Ok(StateSpaceExport {
        format: FORMAT.into(),
        version: VERSION,
        ny: model.ny(),
        nu: model.nu(),
        n_states: ss.n_states(),
        response,
        continuous: Matrices::of(&ss),
        discrete,
        factors: Factors {
            delay_s: f.delay_s,
            derivative_order: f.derivative_order,
            hold: f.hold.name(),
            crosstalk: f.crosstalk.as_ref().map(rows),
            dynamics: f.dynamics.clone(),
        },
        units,
        rank_tol,
        modes: Vec::new(),
        delay_s_std: None,
        dynamics_std: Vec::new(),
    })
}

/// Column-major data and dimensions of a row-major matrix (`rows` x `cols`).
fn column_major(m: &[Vec<f64>], rows: usize, cols: usize) -> (Vec<f64>, [usize; 2]) {
    let mut v = Vec::with_capacity(rows * cols);
    for j in 0..cols {
        for row in m.iter().take(rows) {
            v.push(row[j]);
        }
    }
    (v, [rows, cols])
}

/// Columns of the `.mat` export's `dynamics_roots` table, in order.
pub const DYNAMICS_ROOT_COLUMNS: [&str; 8] = [
    "factor", "zero", "re", "im", "f_hz", "zeta", "f_hz_std", "zeta_std",
];

/// The dynamics factors of `e` as two real tables for the MAT-file (no factor: none):
/// - `dynamics_target`, one row per factor: `[kind, index]` with kind 0 for every entry
///   (index 0), 1 for an input column and 2 for an output row (index 1-based);
/// - `dynamics_roots`, one row per root of each factor, columns
///   [`DYNAMICS_ROOT_COLUMNS`]: the factor (1-based), 0 for a pole and 1 for a zero, the
///   root in rad/s, its natural frequency and damping, and their standard deviations
///   (NaN when the model file holds none, [`StateSpaceExport::dynamics_std`]).
fn dynamics_tables(e: &StateSpaceExport) -> Vec<(String, Vec<f64>, [usize; 2])> {
    use realize::FactorTarget;
    let factors = &e.factors.dynamics;
    if factors.is_empty() {
        return Vec::new();
    }
    let mut target = Vec::new();
    for f in factors {
        let (kind, index) = match f.target {
            FactorTarget::All => (0.0, 0.0),
            FactorTarget::Input(j) => (1.0, (j + 1) as f64),
            FactorTarget::Output(i) => (2.0, (i + 1) as f64),
        };
        target.push([kind, index]);
    }
    let mut rows: Vec<[f64; 8]> = Vec::new();
    for (k, f) in factors.iter().enumerate() {
        let std = e.dynamics_std.get(k);
        for (zero, roots, stds) in [
            (0.0, f.poles(), std.map(|s| &s.poles)),
            (1.0, f.zeros(), std.map(|s| &s.zeros)),
        ] {
            for root in &roots {
                let w = root.norm();
                let (f_hz, zeta) = (w / std::f64::consts::TAU, -root.re / w);
                // the standard deviations of the root with this frequency and damping
                // (a conjugate pair shares one entry)
                let u = stds.and_then(|v| {
                    v.iter().min_by(|a, b| {
                        let d = |u: &frf_data::uncertainty::PoleUncertainty| {
                            (u.f_hz - f_hz).abs() + (u.zeta - zeta).abs() * f_hz
                        };
                        d(a).total_cmp(&d(b))
                    })
                });
                rows.push([
                    (k + 1) as f64,
                    zero,
                    root.re,
                    root.im,
                    f_hz,
                    zeta,
                    u.map_or(f64::NAN, |u| u.f_hz_std),
                    u.map_or(f64::NAN, |u| u.zeta_std),
                ]);
            }
        }
    }
    let column_major = |t: &[Vec<f64>]| -> Vec<f64> {
        let cols = t.first().map_or(0, Vec::len);
        (0..cols)
            .flat_map(|c| t.iter().map(move |row| row[c]))
            .collect()
    };
    let target: Vec<Vec<f64>> = target.iter().map(|r| r.to_vec()).collect();
    let roots: Vec<Vec<f64>> = rows.iter().map(|r| r.to_vec()).collect();
    vec![
        (
            "dynamics_target".into(),
            column_major(&target),
            [target.len(), 2],
        ),
        (
            "dynamics_roots".into(),
            column_major(&roots),
            [roots.len(), DYNAMICS_ROOT_COLUMNS.len()],
        ),
    ]
}

/// The export as a level-5 MAT-file: `A, B, C, D`, `delay_s`, `derivative_order`, and
/// `Ad, Bd, Cd, Dd, Ts` when a discrete equivalent is present, `X` for a crosstalk
/// (MATLAB: `load M.mat; sys = ss(A, B, C, D, 'OutputDelay', delay_s)`). The modes'
/// `f_hz`, `zeta` (with `f_hz_std`, `zeta_std` when known) and the dynamics factors
/// ([`dynamics_tables`]: `dynamics_target`, `dynamics_roots`) go beside them; the
/// factors' coefficients are in the JSON export.
pub fn mat_bytes(e: &StateSpaceExport) -> Vec<u8> {
    let (n, ny, nu) = (e.n_states, e.ny, e.nu);
    let mut store: Vec<(String, Vec<f64>, [usize; 2])> = Vec::new();
    let mut put = |name: &str, m: &Matrices| {
        for (suffix, mat, r, c) in [
            ("A", &m.a, n, n),
            ("B", &m.b, n, nu),
            ("C", &m.c, ny, n),
            ("D", &m.d, ny, nu),
        ] {
            let (v, dims) = column_major(mat, r, c);
            store.push((format!("{suffix}{name}"), v, dims));
        }
    };
    put("", &e.continuous);
    if let Some(d) = &e.discrete {
        put("d", &d.matrices);
        store.push(("Ts".into(), vec![d.ts_s], [1, 1]));
    }
    store.push(("delay_s".into(), vec![e.factors.delay_s], [1, 1]));
    store.push((
        "derivative_order".into(),
        vec![f64::from(e.factors.derivative_order)],
        [1, 1],
    ));
    if let Some(x) = &e.factors.crosstalk {
        let (v, dims) = column_major(x, ny, nu);
        store.push(("X".into(), v, dims));
    }
    // the modal parameters and their standard deviations (NaN where unknown)
    if !e.modes.is_empty() {
        let col =
            |f: &dyn Fn(&ExportedMode) -> f64| -> Vec<f64> { e.modes.iter().map(f).collect() };
        let k = e.modes.len();
        store.push(("f_hz".into(), col(&|m| m.f_hz), [k, 1]));
        store.push(("zeta".into(), col(&|m| m.zeta), [k, 1]));
        if e.modes.iter().any(|m| m.f_hz_std.is_some()) {
            store.push((
                "f_hz_std".into(),
                col(&|m| m.f_hz_std.unwrap_or(f64::NAN)),
                [k, 1],
            ));
            store.push((
                "zeta_std".into(),
                col(&|m| m.zeta_std.unwrap_or(f64::NAN)),
                [k, 1],
            ));
        }
    }
    if let Some(sd) = e.delay_s_std {
        store.push(("delay_s_std".into(), vec![sd], [1, 1]));
    }
    store.push((
        "n_dynamics_factors".into(),
        vec![e.factors.dynamics.len() as f64],
        [1, 1],
    ));
    store.extend(dynamics_tables(e));
    let vars: Vec<MatWrite<'_>> = store
        .iter()
        .map(|(name, v, dims)| MatWrite {
            name,
            dims,
            real: v,
            imag: None,
        })
        .collect();
    mat5_bytes(&vars)
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::io::mat5::{parse_mat5, MatValue};
    use frf_data::uncertainty::PoleUncertainty;
    use realize::{FactorTarget, ModalModel};

    fn pu(f_hz: f64, f_hz_std: f64, zeta: f64, zeta_std: f64) -> PoleUncertainty {
        PoleUncertainty {
            f_hz,
            f_hz_std,
            zeta,
            zeta_std,
        }
    }

    /// The `.mat` export's factor tables: a lead-lag on input 2 and a second-order
    /// factor on every entry, each root with the standard deviations of the model file's
    /// entry of the same frequency and damping (both roots of the conjugate pair).
    #[test]
    fn the_mat_export_holds_the_factors_roots_and_their_standard_deviations() {
        let mut modal = ModalModel::new(2, 2);
        modal.feedthrough = faer::Mat::from_fn(2, 2, |i, j| 1.0 + (i + 2 * j) as f64);
        let mut model = FrfModel::new(modal);
        model.factors.dynamics = vec![
            DynamicsFactor::lead_lag(FactorTarget::Input(1), 300.0, 900.0),
            DynamicsFactor::second_order(FactorTarget::All, 1500.0, 0.05),
        ];
        let mut e = export_state_space(&model, None, 0.0, None).unwrap();
        e.dynamics_std = vec![
            additive_riv::FactorStd {
                poles: vec![pu(900.0, 1.5, 1.0, 0.0)],
                zeros: vec![pu(300.0, 0.5, 1.0, 0.0)],
            },
            additive_riv::FactorStd {
                poles: vec![pu(1500.0, 2.0, 0.05, 0.001)],
                zeros: Vec::new(),
            },
        ];
        let vars = parse_mat5(&mat_bytes(&e), "ss.mat").unwrap();
        let table = |name: &str| -> (Vec<usize>, Vec<f64>) {
            match &vars.iter().find(|v| v.name == name).unwrap().value {
                MatValue::Numeric { dims, real, .. } => (dims.clone(), real.clone()),
                MatValue::Other(k) => panic!("{name} is a {k}"),
            }
        };
        let (dims, target) = table("dynamics_target");
        assert_eq!(dims, vec![2, 2]);
        // column-major: kinds, then indices
        assert_eq!(target, vec![1.0, 0.0, 2.0, 0.0]);
        let (dims, roots) = table("dynamics_roots");
        assert_eq!(dims, vec![4, DYNAMICS_ROOT_COLUMNS.len()]);
        let at = |r: usize, c: &str| {
            let c = DYNAMICS_ROOT_COLUMNS.iter().position(|n| *n == c).unwrap();
            roots[c * 4 + r]
        };
        // the lead-lag's pole, then its zero, then the pair
        let expect = [
            (1.0, 0.0, 900.0, 1.0, 1.5, 0.0),
            (1.0, 1.0, 300.0, 1.0, 0.5, 0.0),
            (2.0, 0.0, 1500.0, 0.05, 2.0, 0.001),
            (2.0, 0.0, 1500.0, 0.05, 2.0, 0.001),
        ];
        for (r, &(factor, zero, f_hz, zeta, sf, sz)) in expect.iter().enumerate() {
            assert_eq!(at(r, "factor"), factor, "row {r}");
            assert_eq!(at(r, "zero"), zero, "row {r}");
            assert!((at(r, "f_hz") / f_hz - 1.0).abs() < 1e-9, "row {r}");
            assert!((at(r, "zeta") - zeta).abs() < 1e-9, "row {r}");
            assert_eq!((at(r, "f_hz_std"), at(r, "zeta_std")), (sf, sz), "row {r}");
        }
        // the pair's roots are conjugate
        assert_eq!(at(2, "im"), -at(3, "im"));
        // without a model file's standard deviations they are NaN
        e.dynamics_std.clear();
        let vars = parse_mat5(&mat_bytes(&e), "ss.mat").unwrap();
        match &vars
            .iter()
            .find(|v| v.name == "dynamics_roots")
            .unwrap()
            .value
        {
            MatValue::Numeric { real, .. } => assert!(real[6 * 4..].iter().all(|v| v.is_nan())),
            MatValue::Other(k) => panic!("{k}"),
        }
    }
}
