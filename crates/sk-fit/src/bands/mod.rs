//! Bayard's multi-band composite fit (Jue, section 2.3; Bayard, ACC 1992): the
//! frequency range is divided into bands, each band's model is an SK fit
//! ([`crate::SkInit`]) of the data minus the other bands' models with the tiered
//! weights of Jue's eq. (3), the bands are fitted in turn until the total error stops
//! falling, and the model is the sum of the band models.
//!
//! - [`BandSpec`]: the cut-offs given (`--bands 4.6,37`, Hz), one band (`--bands 1`),
//!   or chosen from the CMIF (`--bands auto`, the rule of [`auto_cut_offs`]);
//! - [`MultiBandSk`]: the estimator (`frfit fit --init sk --bands ...`), with
//!   [`MultiBandConfig`] and the report [`BandsReport`].

mod auto;
mod composite;
mod spec;

pub use auto::{auto_cut_offs, AutoBands, GapCandidate};
pub use composite::{BandReport, BandsReport, MultiBandConfig, MultiBandSk, PassReport};
pub use spec::BandSpec;
