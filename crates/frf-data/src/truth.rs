//! The truth JSON of the reference and simulated wafer stages
//! (`../shared/data/wafer_*.truth.json`, and what `frfit simulate --truth` writes).
//!
//! Schema: `{"seed", "fs", "delay_s", "effects": {..}, "model": {"b_rb": ny x nu,
//! "modes": [{"f_hz", "zeta", "c": [ny], "b": [nu]}]}}`. The continuous plant is
//! `P(s) = b_rb / s^2 + sum_i c_i b_i^T / (s^2 + 2 zeta_i w_i s + w_i^2)`,
//! `w_i = 2 pi f_hz`; the data are its zero-order-hold discretization at `fs` times one
//! sample of computation delay (`delay_s` = hold + computation = 1.5 samples).

use crate::FrfError;
use faer::Mat;
use realize::{ModalModel, PolePair};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// One flexible mode: `c b^T / (s^2 + 2 zeta w s + w^2)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthMode {
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Relative damping.
    pub zeta: f64,
    /// Sensor mode-shape gains (length `ny`).
    pub c: Vec<f64>,
    /// Actuator mode-shape gains (length `nu`).
    pub b: Vec<f64>,
}

/// The rational plant of a truth file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthModel {
    /// `ny x nu` residue of `1/s^2` (row per output).
    pub b_rb: Vec<Vec<f64>>,
    /// Flexible modes.
    pub modes: Vec<TruthMode>,
}

/// A truth file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Seed of the simulation.
    #[serde(default)]
    pub seed: u64,
    /// The plant.
    pub model: TruthModel,
    /// Effects the nominal model structure does not declare (name -> parameters).
    #[serde(default)]
    pub effects: BTreeMap<String, serde_json::Value>,
    /// Hold + computation delay, seconds.
    #[serde(default)]
    pub delay_s: f64,
    /// Sample rate, Hz.
    #[serde(default)]
    pub fs: f64,
}

impl Truth {
    /// Reads a truth JSON file.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, FrfError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| FrfError::Io {
            file: path.display().to_string(),
            message: e.to_string(),
        })?;
        serde_json::from_str(&text).map_err(|e| {
            FrfError::format(
                path.display().to_string(),
                e.line(),
                None,
                crate::FormatProblem::BadRecord,
                format!("truth JSON does not parse: {e}"),
            )
        })
    }

    /// Number of outputs and inputs.
    pub fn dims(&self) -> (usize, usize) {
        let ny = self.model.b_rb.len();
        let nu = self.model.b_rb.first().map_or(0, Vec::len);
        (ny, nu)
    }

    /// The continuous plant as a [`ModalModel`] (rigid body `b_rb / s^2`, one pole pair
    /// per mode with residue `c b^T / (2 j w_d)`).
    pub fn modal_model(&self) -> Result<ModalModel, FrfError> {
        let (ny, nu) = self.dims();
        if self.model.b_rb.iter().any(|r| r.len() != nu) {
            return Err(FrfError::InvalidData {
                why: "truth b_rb rows have different lengths".into(),
            });
        }
        let mut m = ModalModel::new(ny, nu);
        let b_rb = Mat::from_fn(ny, nu, |i, j| self.model.b_rb[i][j]);
        m.rigid = vec![Mat::zeros(ny, nu), b_rb];
        for (k, md) in self.model.modes.iter().enumerate() {
            if md.c.len() != ny || md.b.len() != nu {
                return Err(FrfError::InvalidData {
                    why: format!(
                        "truth mode {k}: c has {} and b has {} gains, expected {ny} and {nu}",
                        md.c.len(),
                        md.b.len()
                    ),
                });
            }
            let num = Mat::from_fn(ny, nu, |i, j| md.c[i] * md.b[j]);
            m.pairs
                .push(PolePair::from_second_order(md.f_hz, md.zeta, &num));
        }
        m.validate()?;
        Ok(m)
    }
}
