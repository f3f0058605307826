//! # subspace: frequency-domain subspace identification
//!
//! Will hold (a later issue): the frequency-domain subspace algorithm of McKelvey and of
//! Pintelon-Schoukens (eq. (3)-(16)), discrete and continuous time (bilinear map),
//! noise-covariance weighting, model order from the singular values, and B/D by least
//! squares (eq. 17), behind the `frf_data::Estimator` trait (an initialiser).
