//! The groups of entries whose weights are proportional (one noise level, uniform
//! weights): the data [`crate::shared`] evaluates once per group instead of once per
//! entry, formed once when the problem is set up.

use crate::C64;
use faer::Mat;

/// One group of entries with proportional weights.
pub(crate) struct Group {
    /// The entries (indices into `vec(G)`).
    pub entries: Vec<usize>,
    /// The group's `sqrt` weight per line (largest 1): the entry's `sqrt(2 w)` is
    /// `sqrt(scale) * sw`.
    pub sw: Vec<f64>,
    /// Per entry, the scale of its weights.
    pub scale: Vec<f64>,
    /// The group-weighted data, `2N x entries` (real and imaginary rows of every line).
    pub y: Mat<f64>,
}

/// The groups of a problem whose entries share weights.
pub(crate) struct Shared {
    pub groups: Vec<Group>,
}

impl Shared {
    /// The groups of the `sqrt(2 w)` weights `sw` (line after line, each line the `m`
    /// entries) and the data `g`, or `None` when sharing does not pay (fewer than two
    /// entries per group on average).
    pub fn new(sw: &[f64], g: &[C64], m: usize) -> Option<Shared> {
        if m < 2 {
            return None;
        }
        let w2: Vec<f64> = sw.iter().map(|s| s * s).collect();
        let groups = frf_data::proportional_groups(&w2, m, 1e-12);
        if 2 * groups.len() > m {
            return None;
        }
        let nl = sw.len() / m;
        let groups = groups
            .into_iter()
            .map(|gr| {
                let swg: Vec<f64> = gr.line_weights.iter().map(|x| x.sqrt()).collect();
                let y = Mat::from_fn(2 * nl, gr.entries.len(), |r, c| {
                    let k = r / 2;
                    let v = g[k * m + gr.entries[c]] * swg[k];
                    if r % 2 == 0 {
                        v.re
                    } else {
                        v.im
                    }
                });
                Group {
                    entries: gr.entries,
                    sw: swg,
                    scale: gr.scales,
                    y,
                }
            })
            .collect();
        Some(Shared { groups })
    }
}
