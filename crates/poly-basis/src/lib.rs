//! # poly-basis: polynomial bases that keep frequency-domain fits conditioned
//!
//! Will hold (later issues): scaled monomials in `s / w0`, the bilinear (prewarped)
//! z-domain map of McKelvey eq. (39) and Jue section 2.2.1, and Forsythe / orthogonal
//! vector polynomials, each with evaluation at many frequency points and conversion back
//! to monomial coefficients. Used by `sk-fit` and `subspace`. The additive-RIV estimator
//! does not need it: its second-order submodels are scaled per mode.
