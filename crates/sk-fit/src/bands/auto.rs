//! Cut-off frequencies chosen from the CMIF (`--bands auto`).
//!
//! Jue (section 2.3.2) cuts "at an area of zero slope" between resonances and keeps the
//! number of bands small (each band adds a residual that every other band fits again,
//! section 2.3.1), and leaves the choice to the modeller. The rule here:
//!
//! 1. The level `L(k)` is the first singular value of the CMIF in dB at line `k`
//!    (`10 log10 sigma_1^2`), smoothed by a moving average over `2 h + 1` lines; its
//!    slope `S(k)` is in dB per decade (central differences in `log10 f`).
//! 2. The resonances are the CMIF peaks of [`frf_data::cmif::pick_peaks`]; `p` of them.
//! 3. The number of bands is `B = ceil(p / modes_per_band)`, at most `max_bands` and at
//!    most `p` (one band when there are no peaks).
//! 4. Between every two adjacent peaks the candidate cut is the line of the gap with the
//!    smallest score `L(k) + slope_weight |S(k)|`: low in magnitude and flat (a valley
//!    floor between two resonance clusters). The gap's merit is that score minus the
//!    level of the lower of the two peaks (negative; the deeper and flatter, the better).
//! 5. Cut `j` of `B - 1` aims at the gap after peak `round(j p / B)` (equal numbers of
//!    peaks per band) and takes the gap of best merit within `max(1, p / (4 B))` gaps
//!    of that aim (beyond the previous cut, and leaving a gap for each cut still to
//!    come): balance first, then the flattest valley nearby.

use frf_data::cmif::{Cmif, CmifPeak};
use serde::{Deserialize, Serialize};

/// Settings of the automatic cut-offs, with documented defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoBands {
    /// CMIF peaks per band the number of bands aims at. Default: 5 (a CMIF peak often
    /// hides a cluster of close modes: on the plant of Jue's Example 2, 90 modes in 30
    /// clusters, the CMIF shows 14 to 20 peaks and a band of 5 of them needs an SK
    /// order of 40 to 80; the sweep's largest order is 80).
    pub modes_per_band: usize,
    /// Most bands. Default: 4 (Jue: "as few bands as possible").
    pub max_bands: usize,
    /// Half-width `h` of the moving average of the CMIF level, lines. Default: 2.
    pub smooth_lines: usize,
    /// dB of score per dB/decade of slope. Default: 0.1 (a 20 dB/decade flank counts
    /// as 2 dB higher than a flat floor).
    pub slope_weight: f64,
}

impl Default for AutoBands {
    fn default() -> Self {
        Self {
            modes_per_band: 5,
            max_bands: 4,
            smooth_lines: 2,
            slope_weight: 0.1,
        }
    }
}

/// One gap between adjacent CMIF peaks and its best cut.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GapCandidate {
    /// The line of the cut.
    pub line: usize,
    /// Its frequency, Hz.
    pub f_hz: f64,
    /// Smoothed first singular value there, dB.
    pub level_db: f64,
    /// Slope there, dB per decade.
    pub slope_db_per_decade: f64,
    /// Score minus the level of the lower neighbouring peak, dB (lower is better).
    pub merit_db: f64,
}

/// The cut-offs in Hz chosen by the rule of the module documentation, with the
/// candidates they were chosen from.
pub fn auto_cut_offs(cmif: &Cmif, peaks: &[CmifPeak], cfg: &AutoBands) -> Vec<GapCandidate> {
    let l = cmif.n_lines();
    if l < 3 {
        return Vec::new();
    }
    let level: Vec<f64> = cmif
        .sv2
        .iter()
        .map(|s| 10.0 * s.first().copied().unwrap_or(0.0).max(1e-300).log10())
        .collect();
    let h = cfg.smooth_lines;
    let smooth: Vec<f64> = (0..l)
        .map(|k| {
            let (a, b) = (k.saturating_sub(h), (k + h).min(l - 1));
            level[a..=b].iter().sum::<f64>() / (b - a + 1) as f64
        })
        .collect();
    let lf: Vec<f64> = cmif.freq_hz.iter().map(|f| f.max(1e-300).log10()).collect();
    let slope = |k: usize| {
        let (a, b) = (k.saturating_sub(1), (k + 1).min(l - 1));
        let d = lf[b] - lf[a];
        if d > 0.0 {
            (smooth[b] - smooth[a]) / d
        } else {
            0.0
        }
    };
    let mut lines: Vec<usize> = peaks.iter().map(|p| p.line.min(l - 1)).collect();
    lines.sort_unstable();
    lines.dedup();
    let p = lines.len();
    if p < 2 {
        return Vec::new();
    }
    let n_bands = p
        .div_ceil(cfg.modes_per_band.max(1))
        .min(cfg.max_bands.max(1))
        .min(p);
    if n_bands < 2 {
        return Vec::new();
    }
    // the best cut of every gap (None when the peaks are adjacent lines)
    let gaps: Vec<Option<GapCandidate>> = lines
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            ((a + 1)..b)
                .map(|k| {
                    let s = slope(k);
                    (k, smooth[k] + cfg.slope_weight * s.abs(), s)
                })
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .map(|(k, score, s)| GapCandidate {
                    line: k,
                    f_hz: cmif.freq_hz[k],
                    level_db: smooth[k],
                    slope_db_per_decade: s,
                    merit_db: score - smooth[a].min(smooth[b]),
                })
        })
        .collect();
    let radius = (p / (4 * n_bands)).max(1);
    let mut cuts: Vec<GapCandidate> = Vec::new();
    let mut next_gap = 0;
    for j in 1..n_bands {
        // gap g lies between peaks g and g + 1
        let aim = ((j * p) as f64 / n_bands as f64).round() as usize;
        let aim = aim.saturating_sub(1).min(p - 2);
        // beyond the previous cut, and leaving a gap for each cut still to come
        let last = (p - 2).saturating_sub(n_bands - 1 - j);
        let lo = aim.saturating_sub(radius).max(next_gap).min(last);
        let hi = (aim + radius).min(last).max(lo);
        let best = (lo..=hi)
            .filter_map(|g| gaps[g].as_ref().map(|c| (g, c)))
            .min_by(|x, y| x.1.merit_db.total_cmp(&y.1.merit_db));
        if let Some((g, c)) = best {
            cuts.push(c.clone());
            next_gap = g + 1;
        }
        if next_gap > p - 2 {
            break;
        }
    }
    cuts
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::cmif::{cmif, pick_peaks, PeakConfig};
    use frf_data::Frf;
    use realize::{ModalModel, PolePair, C64};

    /// Two clusters of three modes (2-4 Hz and 40-80 Hz): the single cut falls in the
    /// flat valley between them, and with one peak per band the cuts separate every
    /// pair of neighbouring peaks.
    #[test]
    fn cuts_fall_between_clusters() {
        let mut m = ModalModel::new(1, 1);
        for (f, r) in [
            (2.0, 1.0),
            (3.0, 1.0),
            (4.0, 1.0),
            (40.0, 0.1),
            (60.0, 0.1),
            (80.0, 0.1),
        ] {
            m.pairs.push(PolePair::from_f_zeta(
                f,
                0.02,
                faer::Mat::from_fn(1, 1, |_, _| C64::new(0.0, -r * f)),
            ));
        }
        let freq: Vec<f64> = (0..600)
            .map(|k| 1.0 * (150.0f64).powf(k as f64 / 599.0))
            .collect();
        let w: Vec<f64> = freq.iter().map(|f| std::f64::consts::TAU * f).collect();
        let g = m.freq_response(&w).unwrap();
        let data = Frf::new(freq, 1, 1, g.values, None).unwrap();
        let c = cmif(&data).unwrap();
        let peaks = pick_peaks(&c, &PeakConfig::default());
        let mut pf: Vec<f64> = peaks.iter().map(|p| p.f_hz).collect();
        pf.sort_by(f64::total_cmp);
        let p = pf.len();
        assert!(p >= 4 && pf[1] < 5.0 && pf[p - 2] > 35.0, "{pf:?}");
        // half the peaks per band: one cut, in the valley between the clusters
        let cfg = AutoBands {
            modes_per_band: p.div_ceil(2),
            ..Default::default()
        };
        let cuts = auto_cut_offs(&c, &peaks, &cfg);
        assert_eq!(cuts.len(), 1, "{cuts:?}");
        assert!(cuts[0].f_hz > 4.4 && cuts[0].f_hz < 36.0, "{cuts:?}");
        assert!(cuts[0].merit_db < 0.0, "{cuts:?}");
        // one peak per band: a cut between every two neighbouring peaks
        let one = AutoBands {
            modes_per_band: 1,
            max_bands: 10,
            ..Default::default()
        };
        let cuts = auto_cut_offs(&c, &peaks, &one);
        assert_eq!(cuts.len(), p - 1, "{cuts:?}");
        for (j, cut) in cuts.iter().enumerate() {
            assert!(cut.f_hz > pf[j] && cut.f_hz < pf[j + 1], "{cuts:?} {pf:?}");
        }
        // at most max_bands
        let two = AutoBands {
            max_bands: 2,
            ..one
        };
        assert_eq!(auto_cut_offs(&c, &peaks, &two).len(), 1);
        // as many peaks per band as there are: one band, no cut
        let all = AutoBands {
            modes_per_band: p,
            ..Default::default()
        };
        assert!(auto_cut_offs(&c, &peaks, &all).is_empty());
    }
}
