//! Bad input gets a clear error naming what is wrong, never a panic: too few lines for
//! the parameters, non-finite data, a requested mode outside the band, zero weights.

mod common;

use additive_riv::{
    AdditiveFitter, DelayChoice, Domain, FitData, FitterConfig, ModeSelection, RigidBody, RivError,
};
use common::*;
use frf_data::{FrfDataset, Weighting, C64};
use std::sync::Arc;

/// A dataset that wraps another and replaces one value (e.g. by NaN): the
/// `FrfDataset` trait is open, so the estimator must check what it is given.
struct Tampered<'a> {
    inner: &'a frf_data::Frf,
    at: (usize, usize, usize),
    value: C64,
}

impl FrfDataset for Tampered<'_> {
    fn ny(&self) -> usize {
        self.inner.ny()
    }
    fn nu(&self) -> usize {
        self.inner.nu()
    }
    fn n_lines(&self) -> usize {
        self.inner.n_lines()
    }
    fn freq_hz(&self, k: usize) -> f64 {
        self.inner.freq_hz(k)
    }
    fn value(&self, k: usize, i: usize, j: usize) -> C64 {
        if (k, i, j) == self.at {
            self.value
        } else {
            self.inner.value(k, i, j)
        }
    }
    fn variance(&self, k: usize, i: usize, j: usize) -> Option<f64> {
        self.inner.variance(k, i, j)
    }
    fn has_variance(&self) -> bool {
        self.inner.has_variance()
    }
    fn units(&self) -> Option<&str> {
        self.inner.units()
    }
}

fn small_case() -> (Case, frf_data::Frf) {
    let case = random_case(3, 2, 2, 3, true, Domain::Continuous);
    let data = simulate(&case.truth, &case.freqs, 0.0, 3);
    (case, data)
}

#[test]
fn fewer_lines_than_parameters() {
    let (case, data) = small_case();
    // One line at the first mode: 1 x 4 x 2 = 8 real observations for a rigid body
    // (a 2 x 2 numerator) and a mode (2 denominator + 4 numerator parameters).
    let f0 = case.mode_f[0];
    let band = data.band(f0 - 0.4, f0 + 0.4).unwrap();
    assert_eq!(band.n_lines(), 1);
    let cfg = FitterConfig {
        modes: ModeSelection::Frequencies(vec![band.freq_hz(0)]),
        delay: DelayChoice::None,
        rigid_body: RigidBody::Integrators(2),
        adapt: None,
        ..Default::default()
    };
    let err = AdditiveFitter::new(cfg).fit(&band).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, RivError::TooFewData { .. }) || msg.contains("too few"),
        "{msg}"
    );
    assert!(msg.contains("parameters"), "{msg}");
}

#[test]
fn non_finite_value_is_named() {
    let (_case, data) = small_case();
    let bad = Tampered {
        inner: &data,
        at: (17, 1, 0),
        value: C64::new(f64::NAN, 0.0),
    };
    let err = FitData::new(&bad, &Weighting::InverseMagnitude).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("non-finite"), "{msg}");
    assert!(msg.contains("line 17"), "{msg}");
    assert!(msg.contains("G2_1"), "{msg}");
    let err = AdditiveFitter::new(FitterConfig::default())
        .fit(&bad)
        .unwrap_err();
    assert!(err.to_string().contains("non-finite"), "{err}");
}

#[test]
fn requested_mode_outside_band() {
    let (_case, data) = small_case();
    let cfg = FitterConfig {
        modes: ModeSelection::Frequencies(vec![100.0, 5000.0]),
        ..Default::default()
    };
    let err = AdditiveFitter::new(cfg).fit(&data).unwrap_err();
    match &err {
        RivError::ModeOutsideBand { f_hz, .. } => assert_eq!(*f_hz, 5000.0),
        other => panic!("expected ModeOutsideBand, got {other}"),
    }
    assert!(err.to_string().contains("5000"), "{err}");
}

#[test]
fn zero_weights_everywhere() {
    let (_case, data) = small_case();
    let zeros = Weighting::User(Arc::new(vec![0.0; data.n_lines() * data.n_entries()]));
    let err = FitData::new(&data, &zeros).unwrap_err();
    assert!(err.to_string().contains("zero"), "{err}");
    let mut cfg = FitterConfig::default();
    cfg.riv.weighting = zeros;
    let err = AdditiveFitter::new(cfg).fit(&data).unwrap_err();
    assert!(err.to_string().contains("zero"), "{err}");
}

#[test]
fn zero_hz_line_is_refused() {
    let (case, _) = small_case();
    let mut freqs = case.freqs.clone();
    freqs[0] = 0.0;
    let data = simulate(&case.truth.clone(), &freqs[1..], 0.0, 1);
    // Prepend a 0 Hz line with a finite value: integrators are infinite there.
    let m = data.n_entries();
    let mut vals = vec![C64::new(1.0, 0.0); m];
    vals.extend_from_slice(data.values());
    let mut f = vec![0.0];
    f.extend_from_slice(&freqs[1..]);
    let with_dc = frf_data::Frf::new(f, data.ny(), data.nu(), vals, None).unwrap();
    let err = FitData::new(&with_dc, &Weighting::InverseMagnitude).unwrap_err();
    assert!(err.to_string().contains("0 Hz"), "{err}");
}
