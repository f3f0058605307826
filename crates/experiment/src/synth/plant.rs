//! [`ModalPlant`]: the continuous modal plant of a simulated motion system, and its
//! exact sampled (zero-order hold + delay) realisation for time-domain simulation.
//!
//! The plant is the additive structure of the wafer-stage paper (van der Hulst et al.,
//! eq. (1)-(6)): a rigid-body part `b_rb / s^2` (or `b_rb / (s^2 + 2 zeta w s + w^2)` when
//! the body is suspended), flexible modes `c b^T / (s^2 + 2 zeta_i w_i s + w_i^2)` with a
//! rank-one residue made of sensor gains `c` and actuator gains `b`, and an optional
//! feedthrough `D`.

use faer::Mat;
use frf_data::truth::{Truth, TruthMode, TruthModel};
use frf_data::{FrfError, C64};
use realize::{ModalModel, PolePair, ResponseGrid};
use std::collections::BTreeMap;
use std::f64::consts::TAU;

/// One flexible mode `c b^T / (s^2 + 2 zeta w s + w^2)`, `w = 2 pi f_hz`.
#[derive(Debug, Clone, PartialEq)]
pub struct FlexibleMode {
    /// Natural frequency, Hz.
    pub f_hz: f64,
    /// Relative damping, `0 <= zeta < 1`.
    pub zeta: f64,
    /// Sensor mode-shape gains (length `ny`).
    pub c: Vec<f64>,
    /// Actuator mode-shape gains (length `nu`).
    pub b: Vec<f64>,
}

/// The low-frequency (rigid-body) part of the plant.
#[derive(Debug, Clone, PartialEq)]
pub enum RigidBody {
    /// No rigid-body part.
    None,
    /// A free body: `residue / s^2` (`ny x nu`, typically of rank 3 for z, Rx, Ry).
    Free {
        /// The residue of `1/s^2`.
        residue: Mat<f64>,
    },
    /// A body on a suspension stiffness: `residue / (s^2 + 2 zeta w s + w^2)`.
    Suspended {
        /// The numerator matrix.
        residue: Mat<f64>,
        /// Suspension frequency, Hz.
        f_hz: f64,
        /// Suspension damping.
        zeta: f64,
    },
}

impl RigidBody {
    /// The residue matrix, when there is a rigid-body part.
    pub fn residue(&self) -> Option<&Mat<f64>> {
        match self {
            RigidBody::None => None,
            RigidBody::Free { residue } | RigidBody::Suspended { residue, .. } => Some(residue),
        }
    }
}

/// A continuous-time modal plant (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct ModalPlant {
    ny: usize,
    nu: usize,
    /// The rigid-body part.
    pub rigid: RigidBody,
    /// The flexible modes, in increasing frequency.
    pub modes: Vec<FlexibleMode>,
    /// Optional feedthrough `D` (`ny x nu`).
    pub feedthrough: Option<Mat<f64>>,
}

/// Builder of a [`ModalPlant`]; [`ModalPlantBuilder::build`] checks every dimension and
/// value.
#[derive(Debug, Clone)]
pub struct ModalPlantBuilder {
    ny: usize,
    nu: usize,
    rigid: RigidBody,
    modes: Vec<FlexibleMode>,
    feedthrough: Option<Mat<f64>>,
}

impl ModalPlantBuilder {
    /// A plant with `ny` outputs, `nu` inputs and nothing in it yet.
    pub fn new(ny: usize, nu: usize) -> Self {
        Self {
            ny,
            nu,
            rigid: RigidBody::None,
            modes: Vec::new(),
            feedthrough: None,
        }
    }
    /// A free rigid body `residue / s^2`.
    pub fn rigid_body(mut self, residue: Mat<f64>) -> Self {
        self.rigid = RigidBody::Free { residue };
        self
    }
    /// A suspended body `residue / (s^2 + 2 zeta w s + w^2)` instead of a free one.
    pub fn suspended_body(mut self, residue: Mat<f64>, f_hz: f64, zeta: f64) -> Self {
        self.rigid = RigidBody::Suspended {
            residue,
            f_hz,
            zeta,
        };
        self
    }
    /// Adds a flexible mode with sensor gains `c` and actuator gains `b`.
    pub fn mode(mut self, f_hz: f64, zeta: f64, c: Vec<f64>, b: Vec<f64>) -> Self {
        self.modes.push(FlexibleMode { f_hz, zeta, c, b });
        self
    }
    /// A feedthrough `D`.
    pub fn feedthrough(mut self, d: Mat<f64>) -> Self {
        self.feedthrough = Some(d);
        self
    }
    /// Checks and builds the plant; modes are sorted by frequency.
    pub fn build(self) -> Result<ModalPlant, FrfError> {
        let ModalPlantBuilder {
            ny,
            nu,
            rigid,
            mut modes,
            feedthrough,
        } = self;
        if ny == 0 || nu == 0 {
            return Err(FrfError::invalid(
                "plant dimensions",
                format!("{ny}x{nu}"),
                "a plant needs at least one output and one input",
            ));
        }
        let check_mat = |what: &str, m: &Mat<f64>| -> Result<(), FrfError> {
            if m.nrows() != ny || m.ncols() != nu {
                return Err(FrfError::Dimension {
                    what: what.into(),
                    expected: format!("{ny}x{nu}"),
                    got: format!("{}x{}", m.nrows(), m.ncols()),
                });
            }
            if !(0..nu).all(|j| (0..ny).all(|i| m[(i, j)].is_finite())) {
                return Err(FrfError::InvalidData {
                    why: format!("{what} has a non-finite entry"),
                });
            }
            Ok(())
        };
        let check_fz = |what: &str, f: f64, z: f64| -> Result<(), FrfError> {
            if !(f.is_finite() && f > 0.0) {
                return Err(FrfError::invalid(
                    format!("{what} frequency"),
                    f,
                    "must be finite and > 0 Hz",
                ));
            }
            if !(z.is_finite() && (0.0..1.0).contains(&z)) {
                return Err(FrfError::invalid(
                    format!("{what} damping"),
                    z,
                    "must be in [0, 1)",
                ));
            }
            Ok(())
        };
        match &rigid {
            RigidBody::None => {}
            RigidBody::Free { residue } => check_mat("rigid-body residue", residue)?,
            RigidBody::Suspended {
                residue,
                f_hz,
                zeta,
            } => {
                check_mat("suspension residue", residue)?;
                check_fz("suspension", *f_hz, *zeta)?;
            }
        }
        for (k, m) in modes.iter().enumerate() {
            check_fz(&format!("mode {k}"), m.f_hz, m.zeta)?;
            if m.c.len() != ny || m.b.len() != nu {
                return Err(FrfError::Dimension {
                    what: format!("mode {k} gains (c, b)"),
                    expected: format!("({ny}, {nu})"),
                    got: format!("({}, {})", m.c.len(), m.b.len()),
                });
            }
            if !m.c.iter().chain(&m.b).all(|x| x.is_finite()) {
                return Err(FrfError::InvalidData {
                    why: format!("mode {k} has a non-finite gain"),
                });
            }
        }
        if let Some(d) = &feedthrough {
            check_mat("feedthrough", d)?;
        }
        modes.sort_by(|a, b| a.f_hz.total_cmp(&b.f_hz));
        Ok(ModalPlant {
            ny,
            nu,
            rigid,
            modes,
            feedthrough,
        })
    }
}

impl ModalPlant {
    /// A builder for a plant with `ny` outputs and `nu` inputs.
    pub fn builder(ny: usize, nu: usize) -> ModalPlantBuilder {
        ModalPlantBuilder::new(ny, nu)
    }

    /// Number of outputs.
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Number of inputs.
    pub fn nu(&self) -> usize {
        self.nu
    }

    /// The plant of a truth file: `model.b_rb`, `model.modes`, and the declared effects
    /// `crosstalk_D` (feedthrough), `hidden_mode` (one more mode) and `suspension`
    /// (`{"f_hz", "zeta"}`: `b_rb` is then the numerator of a suspension mode). The
    /// delay effect `extra_delay_us` is not part of the plant: see
    /// [`truth_delay_samples`].
    pub fn from_truth(truth: &Truth) -> Result<Self, FrfError> {
        let (ny, nu) = truth.dims();
        if truth.model.b_rb.iter().any(|r| r.len() != nu) {
            return Err(FrfError::InvalidData {
                why: "truth b_rb rows have different lengths".into(),
            });
        }
        let b_rb = Mat::from_fn(ny, nu, |i, j| truth.model.b_rb[i][j]);
        let mut builder = ModalPlant::builder(ny, nu);
        let rigid_nonzero = (0..nu).any(|j| (0..ny).any(|i| b_rb[(i, j)] != 0.0));
        if let Some(s) = truth.effects.get("suspension") {
            let f = s.get("f_hz").and_then(|v| v.as_f64());
            let z = s.get("zeta").and_then(|v| v.as_f64());
            match (f, z) {
                (Some(f), Some(z)) => builder = builder.suspended_body(b_rb, f, z),
                _ => {
                    return Err(FrfError::InvalidData {
                        why: "truth effect `suspension` needs numbers `f_hz` and `zeta`".into(),
                    })
                }
            }
        } else if rigid_nonzero {
            builder = builder.rigid_body(b_rb);
        }
        for m in &truth.model.modes {
            builder = builder.mode(m.f_hz, m.zeta, m.c.clone(), m.b.clone());
        }
        if let Some(h) = truth.effects.get("hidden_mode") {
            let m: TruthMode =
                serde_json::from_value(h.clone()).map_err(|e| FrfError::InvalidData {
                    why: format!("truth effect `hidden_mode` does not parse: {e}"),
                })?;
            builder = builder.mode(m.f_hz, m.zeta, m.c, m.b);
        }
        if let Some(d) = truth.effects.get("crosstalk_D") {
            let rows: Vec<Vec<f64>> =
                serde_json::from_value(d.clone()).map_err(|e| FrfError::InvalidData {
                    why: format!("truth effect `crosstalk_D` does not parse: {e}"),
                })?;
            if rows.len() != ny || rows.iter().any(|r| r.len() != nu) {
                return Err(FrfError::Dimension {
                    what: "truth effect crosstalk_D".into(),
                    expected: format!("{ny}x{nu}"),
                    got: format!("{}x{}", rows.len(), rows.first().map_or(0, Vec::len)),
                });
            }
            builder = builder.feedthrough(Mat::from_fn(ny, nu, |i, j| rows[i][j]));
        }
        builder.build()
    }

    /// The truth JSON of this plant (schema of `wafer_nominal.truth.json`): `b_rb` is the
    /// rigid-body residue (zero when there is none); a suspension and a feedthrough are
    /// written as the effects `suspension` and `crosstalk_D`.
    pub fn to_truth(&self, seed: u64, fs: f64, delay_s: f64) -> Truth {
        let (ny, nu) = (self.ny, self.nu);
        let zero = Mat::zeros(ny, nu);
        let res = self.rigid.residue().unwrap_or(&zero);
        let b_rb = (0..ny)
            .map(|i| (0..nu).map(|j| res[(i, j)]).collect())
            .collect();
        let modes = self
            .modes
            .iter()
            .map(|m| TruthMode {
                f_hz: m.f_hz,
                zeta: m.zeta,
                c: m.c.clone(),
                b: m.b.clone(),
            })
            .collect();
        let mut effects = BTreeMap::new();
        if let RigidBody::Suspended { f_hz, zeta, .. } = &self.rigid {
            effects.insert(
                "suspension".to_string(),
                serde_json::json!({ "f_hz": f_hz, "zeta": zeta }),
            );
        }
        if let Some(d) = &self.feedthrough {
            let rows: Vec<Vec<f64>> = (0..ny)
                .map(|i| (0..nu).map(|j| d[(i, j)]).collect())
                .collect();
            effects.insert("crosstalk_D".to_string(), serde_json::json!(rows));
        }
        Truth {
            seed,
            model: TruthModel { b_rb, modes },
            effects,
            delay_s,
            fs,
        }
    }

    /// The plant as a [`ModalModel`]: `rigid[1] = b_rb` for a free body, one pole pair per
    /// flexible mode (and for the suspension) from [`PolePair::from_second_order`].
    pub fn modal_model(&self) -> Result<ModalModel, FrfError> {
        let mut m = ModalModel::new(self.ny, self.nu);
        match &self.rigid {
            RigidBody::None => {}
            RigidBody::Free { residue } => {
                m.rigid = vec![Mat::zeros(self.ny, self.nu), residue.clone()];
            }
            RigidBody::Suspended {
                residue,
                f_hz,
                zeta,
            } => m
                .pairs
                .push(PolePair::from_second_order(*f_hz, *zeta, residue)),
        }
        for md in &self.modes {
            let num = Mat::from_fn(self.ny, self.nu, |i, j| md.c[i] * md.b[j]);
            m.pairs
                .push(PolePair::from_second_order(md.f_hz, md.zeta, &num));
        }
        if let Some(d) = &self.feedthrough {
            m.feedthrough = d.clone();
        }
        m.validate()?;
        Ok(m)
    }

    /// The exact sampled response: zero-order hold at `fs` and `delay_samples` samples of
    /// extra delay, at `z = exp(j 2 pi f / fs)` (McKelvey, Section 2.3: a piecewise-constant
    /// input makes the sampled system exactly discrete), via
    /// [`ModalModel::zoh_response`].
    pub fn sampled_response(
        &self,
        freq_hz: &[f64],
        fs: f64,
        delay_samples: f64,
    ) -> Result<ResponseGrid, FrfError> {
        if !(fs.is_finite() && fs > 0.0) {
            return Err(FrfError::invalid("fs", fs, "must be finite and > 0 Hz"));
        }
        let omega: Vec<f64> = freq_hz.iter().map(|f| TAU * f).collect();
        Ok(self
            .modal_model()?
            .zoh_response(&omega, 1.0 / fs, delay_samples)?)
    }

    /// The continuous response `P(j 2 pi f)`.
    pub fn continuous_response(&self, freq_hz: &[f64]) -> Result<ResponseGrid, FrfError> {
        let omega: Vec<f64> = freq_hz.iter().map(|f| TAU * f).collect();
        Ok(self.modal_model()?.freq_response(&omega)?)
    }

    /// The exact ZOH discretisation at sample time `ts` as a [`DiscreteModalPlant`], for
    /// time-domain simulation.
    pub fn discretize(&self, ts: f64) -> Result<DiscreteModalPlant, FrfError> {
        DiscreteModalPlant::new(self, ts)
    }
}

/// The total loop delay in samples declared by a truth file: `delay_s * fs - 0.5` (the
/// hold's half sample is part of the ZOH response), plus `effects.extra_delay_us`;
/// snapped to a whole number of samples when within `1e-9` of one.
pub fn truth_delay_samples(truth: &Truth) -> Result<f64, FrfError> {
    if !(truth.fs.is_finite() && truth.fs > 0.0) {
        return Err(FrfError::invalid(
            "truth fs",
            truth.fs,
            "must be finite and > 0 Hz",
        ));
    }
    let mut d = truth.delay_s * truth.fs - 0.5;
    if let Some(x) = truth.effects.get("extra_delay_us").and_then(|v| v.as_f64()) {
        d += x * 1e-6 * truth.fs;
    }
    // 150 us * 10 kHz - 0.5 is 0.9999999999999998 in floating point: snap to whole
    // samples within 1e-9 (the time-domain simulation needs a whole number)
    if (d - d.round()).abs() < 1e-9 {
        d = d.round();
    }
    if !(d.is_finite() && d >= 0.0) {
        return Err(FrfError::invalid(
            "truth delay_s",
            truth.delay_s,
            "gives a negative computation delay (delay_s must be >= half a sample)",
        ));
    }
    Ok(d)
}

/// A block of complex first-order modal states sharing one discrete pole:
/// `xi[k+1] = zp xi[k] + g (R u[k])`, contribution `2 Re(s L xi[k])` to `y[k]`.
///
/// This is the closed-form ZOH discretisation of `s L R / (s - p)` plus its conjugate
/// (the same term-by-term map as [`ModalModel::zoh_response`]: `g = (e^{p ts} - 1)/p`,
/// `zp = e^{p ts}`).
#[derive(Debug, Clone)]
pub(crate) struct ComplexBlock {
    pub zp: C64,
    pub g: C64,
    /// Output scale `s` (the residue is `s L R`).
    pub s: C64,
    /// `ny x r` output factor, column-major.
    pub l: Vec<f64>,
    /// `r x nu` input factor, row-major (row q = input gains of state q).
    pub r: Vec<f64>,
    pub rank: usize,
}

/// The exact ZOH discretisation of a [`ModalPlant`] in modal coordinates: one complex
/// state per rank of each oscillatory term, a double integrator per rank of the free
/// rigid body. State update per sample costs `O(n_states * (ny + nu))`.
#[derive(Debug, Clone)]
pub struct DiscreteModalPlant {
    pub(crate) ny: usize,
    pub(crate) nu: usize,
    pub(crate) ts: f64,
    pub(crate) blocks: Vec<ComplexBlock>,
    /// Rigid-body factors: `b_rb = L R` with `L` `ny x r` (column-major), `R` `r x nu`
    /// (row-major); empty when the body is not free.
    pub(crate) rb_l: Vec<f64>,
    pub(crate) rb_r: Vec<f64>,
    pub(crate) rb_rank: usize,
    pub(crate) d: Option<Vec<f64>>, // ny x nu column-major
}

/// The state of a [`DiscreteModalPlant`].
#[derive(Debug, Clone)]
pub struct DiscreteModalState {
    xi: Vec<C64>,
    q: Vec<f64>,
    v: Vec<f64>,
}

/// Rank-revealing factorisation `M = L R` of a real matrix by the SVD (faer), `L = U S`,
/// `R = V^T`, singular values below `1e-12 * s_max` dropped. Returns `(L col-major ny x r,
/// R row-major r x nu, r)`.
pub(crate) fn low_rank_factors(m: &Mat<f64>) -> Result<(Vec<f64>, Vec<f64>, usize), FrfError> {
    let (ny, nu) = (m.nrows(), m.ncols());
    let svd = m.thin_svd().map_err(|e| FrfError::Numerical {
        what: "SVD of a residue matrix".into(),
        why: format!("{e:?}"),
    })?;
    let s = svd.S().column_vector();
    let smax = (0..s.nrows()).map(|i| s[i]).fold(0.0, f64::max);
    let r = (0..s.nrows()).filter(|&i| s[i] > 1e-12 * smax).count();
    let (u, v) = (svd.U(), svd.V());
    let mut l = vec![0.0; ny * r];
    let mut rr = vec![0.0; r * nu];
    for q in 0..r {
        for i in 0..ny {
            l[q * ny + i] = u[(i, q)] * s[q];
        }
        for j in 0..nu {
            rr[q * nu + j] = v[(j, q)];
        }
    }
    Ok((l, rr, r))
}

fn zoh_pole(p: C64, ts: f64) -> (C64, C64) {
    let zp = (p * ts).exp();
    let x = p * ts;
    let g = if x.norm() < 1e-5 {
        ts * (C64::new(1.0, 0.0) + x / 2.0 + x * x / 6.0)
    } else {
        (zp - 1.0) / p
    };
    (zp, g)
}

fn second_order_pole(f_hz: f64, zeta: f64) -> (C64, f64) {
    let wn = TAU * f_hz;
    let wd = wn * (1.0 - zeta * zeta).max(0.0).sqrt();
    (C64::new(-zeta * wn, wd), wd)
}

impl DiscreteModalPlant {
    fn new(plant: &ModalPlant, ts: f64) -> Result<Self, FrfError> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(FrfError::invalid("ts", ts, "must be finite and > 0 s"));
        }
        let (ny, nu) = (plant.ny, plant.nu);
        let mut blocks = Vec::new();
        let mut push_block = |f_hz: f64, zeta: f64, l: Vec<f64>, r: Vec<f64>, rank: usize| {
            let (p, wd) = second_order_pole(f_hz, zeta);
            let (zp, g) = zoh_pole(p, ts);
            // residue of p for numerator N is N / (2 j wd) = N * (-j / (2 wd))
            let s = C64::new(0.0, -1.0 / (2.0 * wd));
            blocks.push(ComplexBlock {
                zp,
                g,
                s,
                l,
                r,
                rank,
            });
        };
        let (mut rb_l, mut rb_r, mut rb_rank) = (Vec::new(), Vec::new(), 0);
        match &plant.rigid {
            RigidBody::None => {}
            RigidBody::Free { residue } => {
                let (l, r, k) = low_rank_factors(residue)?;
                rb_l = l;
                rb_r = r;
                rb_rank = k;
            }
            RigidBody::Suspended {
                residue,
                f_hz,
                zeta,
            } => {
                let (l, r, k) = low_rank_factors(residue)?;
                push_block(*f_hz, *zeta, l, r, k);
            }
        }
        for m in &plant.modes {
            push_block(m.f_hz, m.zeta, m.c.clone(), m.b.clone(), 1);
        }
        let d = plant.feedthrough.as_ref().map(|d| {
            (0..nu)
                .flat_map(|j| (0..ny).map(move |i| d[(i, j)]))
                .collect()
        });
        Ok(Self {
            ny,
            nu,
            ts,
            blocks,
            rb_l,
            rb_r,
            rb_rank,
            d,
        })
    }

    /// Number of outputs.
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Number of inputs.
    pub fn nu(&self) -> usize {
        self.nu
    }
    /// Number of real states of the realisation.
    pub fn n_states(&self) -> usize {
        2 * self.blocks.iter().map(|b| b.rank).sum::<usize>() + 2 * self.rb_rank
    }

    /// The zero state (system at rest).
    pub fn zero_state(&self) -> DiscreteModalState {
        DiscreteModalState {
            xi: vec![C64::new(0.0, 0.0); self.blocks.iter().map(|b| b.rank).sum()],
            q: vec![0.0; self.rb_rank],
            v: vec![0.0; self.rb_rank],
        }
    }

    /// The output `y[k] = C x[k] + D u[k]` for the held input `u[k]` into `y`.
    pub fn output(&self, x: &DiscreteModalState, u: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        let ny = self.ny;
        let mut idx = 0;
        for b in &self.blocks {
            for q in 0..b.rank {
                let w = 2.0 * (b.s * x.xi[idx]).re;
                let col = &b.l[q * ny..(q + 1) * ny];
                for i in 0..ny {
                    y[i] += col[i] * w;
                }
                idx += 1;
            }
        }
        for q in 0..self.rb_rank {
            let col = &self.rb_l[q * ny..(q + 1) * ny];
            for i in 0..ny {
                y[i] += col[i] * x.q[q];
            }
        }
        if let Some(d) = &self.d {
            for j in 0..self.nu {
                for i in 0..ny {
                    y[i] += d[j * ny + i] * u[j];
                }
            }
        }
    }

    /// Advances the state by one sample with the input `u` held constant over it.
    pub fn step(&self, x: &mut DiscreteModalState, u: &[f64]) {
        let nu = self.nu;
        let ts = self.ts;
        let mut idx = 0;
        for b in &self.blocks {
            for q in 0..b.rank {
                let row = &b.r[q * nu..(q + 1) * nu];
                let f: f64 = row.iter().zip(u).map(|(a, b)| a * b).sum();
                x.xi[idx] = b.zp * x.xi[idx] + b.g * f;
                idx += 1;
            }
        }
        for q in 0..self.rb_rank {
            let row = &self.rb_r[q * nu..(q + 1) * nu];
            let f: f64 = row.iter().zip(u).map(|(a, b)| a * b).sum();
            let v0 = x.v[q];
            x.q[q] += ts * v0 + 0.5 * ts * ts * f;
            x.v[q] = v0 + ts * f;
        }
    }

    /// The real state-space matrices `(A, B, C, D)` of this realisation (states ordered
    /// as complex blocks `[Re xi, Im xi]`, then rigid-body `[q, v]` pairs), used to check
    /// closed-loop poles.
    pub fn real_matrices(&self) -> (Mat<f64>, Mat<f64>, Mat<f64>, Mat<f64>) {
        let (ny, nu, n) = (self.ny, self.nu, self.n_states());
        let mut a = Mat::<f64>::zeros(n, n);
        let mut bm = Mat::<f64>::zeros(n, nu);
        let mut c = Mat::<f64>::zeros(ny, n);
        let mut k = 0;
        for blk in &self.blocks {
            for q in 0..blk.rank {
                let (re, im) = (k, k + 1);
                a[(re, re)] = blk.zp.re;
                a[(re, im)] = -blk.zp.im;
                a[(im, re)] = blk.zp.im;
                a[(im, im)] = blk.zp.re;
                for j in 0..nu {
                    let r = blk.r[q * nu + j];
                    bm[(re, j)] = blk.g.re * r;
                    bm[(im, j)] = blk.g.im * r;
                }
                // 2 Re(s (xr + j xi)) = 2 (s.re xr - s.im xi)
                for i in 0..ny {
                    let l = blk.l[q * ny + i];
                    c[(i, re)] = 2.0 * blk.s.re * l;
                    c[(i, im)] = -2.0 * blk.s.im * l;
                }
                k += 2;
            }
        }
        let ts = self.ts;
        for q in 0..self.rb_rank {
            let (qi, vi) = (k, k + 1);
            a[(qi, qi)] = 1.0;
            a[(qi, vi)] = ts;
            a[(vi, vi)] = 1.0;
            for j in 0..nu {
                let r = self.rb_r[q * nu + j];
                bm[(qi, j)] = 0.5 * ts * ts * r;
                bm[(vi, j)] = ts * r;
            }
            for i in 0..ny {
                c[(i, qi)] = self.rb_l[q * ny + i];
            }
            k += 2;
        }
        let d = Mat::from_fn(ny, nu, |i, j| {
            self.d.as_ref().map_or(0.0, |d| d[j * ny + i])
        });
        (a, bm, c, d)
    }
}
