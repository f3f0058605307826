//! The options of a fit as a user writes them (`--hold zoh:10000`, `--delay 150us`,
//! `--band 20:2000`, ...), parsed once for every front end: the `frfit` command line and
//! the Python package both turn their strings into a [`FitSpec`] and that into a
//! [`PipelineConfig`], so that the same words mean the same fit everywhere.
//!
//! Every parser returns an error message that names the value and what is expected;
//! [`FitSpec::pipeline_config`] and [`FitSpec::check`] are the only places where the
//! options become a configuration.

use crate::chain::SkBands;
use crate::pipeline::{FrfType, PipelineConfig};
use crate::FrfitError;
use additive_riv::{DelayChoice, Hold, IvMethod, ModeSelection};
use frf_data::{Frf, FrfDataset, FrfView, Weighting};
use sk_fit::bands::BandSpec;

/// A frequency band `LO:HI` in Hz; either side may be left open (`20:` is from 20 Hz up,
/// `:500` up to 500 Hz).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Band {
    /// Lower edge, Hz (`None`: the first line).
    pub lo_hz: Option<f64>,
    /// Upper edge, Hz (`None`: the last line).
    pub hi_hz: Option<f64>,
}

impl Band {
    /// A closed band `lo_hz..hi_hz`, checked like [`parse_band`].
    pub fn new(lo_hz: Option<f64>, hi_hz: Option<f64>) -> Result<Self, String> {
        for (v, which) in [(lo_hz, "lower"), (hi_hz, "upper")] {
            if let Some(v) = v {
                if !v.is_finite() || v < 0.0 {
                    return Err(format!("{which} band edge {v} must be finite and >= 0 Hz"));
                }
            }
        }
        if let (Some(l), Some(h)) = (lo_hz, hi_hz) {
            if l >= h {
                return Err(format!("band {l}:{h}: LO must be below HI"));
            }
        }
        Ok(Self { lo_hz, hi_hz })
    }

    /// The band as the pipeline takes it (open sides at 0 Hz and `f64::MAX`).
    pub fn as_range(&self) -> (f64, f64) {
        (self.lo_hz.unwrap_or(0.0), self.hi_hz.unwrap_or(f64::MAX))
    }
}

/// Parses `LO:HI` (Hz).
pub fn parse_band(s: &str) -> Result<Band, String> {
    let Some((a, b)) = s.split_once(':') else {
        return Err(format!(
            "expected LO:HI in Hz (e.g. 20:2000, 20: or :500), got `{s}`"
        ));
    };
    let side = |t: &str, which: &str| -> Result<Option<f64>, String> {
        let t = t.trim();
        if t.is_empty() {
            return Ok(None);
        }
        let v: f64 = t
            .parse()
            .map_err(|_| format!("{which} edge `{t}` of band `{s}` is not a number"))?;
        if !v.is_finite() || v < 0.0 {
            return Err(format!(
                "{which} edge {v} of band `{s}` must be finite and >= 0 Hz"
            ));
        }
        Ok(Some(v))
    };
    let lo = side(a, "lower")?;
    let hi = side(b, "upper")?;
    if let (Some(l), Some(h)) = (lo, hi) {
        if l >= h {
            return Err(format!("band `{s}`: LO must be below HI"));
        }
    }
    Ok(Band {
        lo_hz: lo,
        hi_hz: hi,
    })
}

/// The lines of `data` inside `band` (all lines for `None`). A band that holds no line of
/// the data is an error naming both the requested band and the range of the data.
pub fn select_band(data: &Frf, band: Option<Band>) -> Result<FrfView<'_>, FrfitError> {
    let view = data.view();
    let n = data.n_lines();
    if n == 0 {
        return Err(FrfitError::argument(
            "data",
            data.source.as_deref().unwrap_or("<data>"),
            "the file holds no frequency lines",
        ));
    }
    let Some(b) = band else { return Ok(view) };
    let (f0, f1) = (data.freq_hz(0), data.freq_hz(n - 1));
    let lo = b.lo_hz.unwrap_or(f0.min(0.0));
    let hi = b.hi_hz.unwrap_or(f64::MAX);
    view.band(lo, hi).map_err(|_| {
        FrfitError::argument(
            "--band",
            format!("{}:{}", fmt_edge(b.lo_hz), fmt_edge(b.hi_hz)),
            format!(
                "the band holds no frequency line of the data, which span {} .. {} Hz",
                fmt_num(f0),
                fmt_num(f1)
            ),
        )
    })
}

fn fmt_edge(v: Option<f64>) -> String {
    v.map(fmt_num).unwrap_or_default()
}

/// A number with 6 significant digits, without trailing zeros.
pub fn fmt_num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if (1e-3..1e6).contains(&a) {
        let digits = (5 - a.log10().floor() as i32).clamp(0, 9) as usize;
        let s = format!("{v:.digits$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        let s = format!("{v:.4e}");
        match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    }
}

/// Parses `zoh:FS | sinc:FS | none` (`none` overrides a hold the file declares).
pub fn parse_hold(s: &str) -> Result<Hold, String> {
    let s = s.trim();
    if s.eq_ignore_ascii_case("none") {
        return Ok(Hold::None);
    }
    let (kind, fs) = s
        .split_once(':')
        .ok_or_else(|| format!("expected zoh:FS_HZ, sinc:FS_HZ or none, got `{s}`"))?;
    let fs: f64 = fs
        .trim()
        .parse()
        .map_err(|_| format!("sample rate `{fs}` in `{s}` is not a number (Hz)"))?;
    if !(fs.is_finite() && fs > 0.0) {
        return Err(format!("sample rate {fs} in `{s}` must be > 0 Hz"));
    }
    match kind.trim().to_ascii_lowercase().as_str() {
        "zoh" => Ok(Hold::Zoh { fs_hz: fs }),
        "sinc" => Ok(Hold::Sinc { fs_hz: fs }),
        k => Err(format!(
            "unknown hold `{k}`: use zoh:FS_HZ (exact) or sinc:FS_HZ"
        )),
    }
}

/// Parses `auto | 1 | F1,F2,...` (cut-offs in Hz) of the multi-band SK fit.
pub fn parse_bands(s: &str) -> Result<BandSpec, String> {
    BandSpec::parse(s).map_err(|e| e.to_string())
}

/// Parses `QL,QH`, both in `[0, 1]`.
pub fn parse_band_weights(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("expected QL,QH (e.g. 0.1,1e-4), got `{s}`"))?;
    let q = |name: &str, v: &str| -> Result<f64, String> {
        let x: f64 = v
            .trim()
            .parse()
            .map_err(|_| format!("{name} `{}` in `{s}` is not a number", v.trim()))?;
        if !(0.0..=1.0).contains(&x) {
            return Err(format!("{name} {x} in `{s}` must lie in [0, 1]"));
        }
        Ok(x)
    };
    Ok((q("QL", a)?, q("QH", b)?))
}

/// Parses `auto | none | SECONDS` (also `150us`, `0.2ms`).
pub fn parse_delay(s: &str) -> Result<DelayChoice, String> {
    let t = s.trim().to_ascii_lowercase();
    match t.as_str() {
        "auto" => return Ok(DelayChoice::Auto),
        "none" | "0" => return Ok(DelayChoice::None),
        _ => {}
    }
    let (num, scale) = if let Some(v) = t.strip_suffix("us") {
        (v, 1e-6)
    } else if let Some(v) = t.strip_suffix("ms") {
        (v, 1e-3)
    } else if let Some(v) = t.strip_suffix('s') {
        (v, 1.0)
    } else {
        (t.as_str(), 1.0)
    };
    let v: f64 = num.trim().parse().map_err(|_| {
        format!("expected auto, none or a delay in seconds (e.g. 1.5e-4 or 150us), got `{s}`")
    })?;
    if !v.is_finite() || v < 0.0 {
        return Err(format!("delay `{s}` must be finite and >= 0"));
    }
    Ok(DelayChoice::Fixed { seconds: v * scale })
}

/// Parses `auto | N`.
pub fn parse_modes(s: &str) -> Result<ModeSelection, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(ModeSelection::Auto);
    }
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("expected auto or a number of modes, got `{s}`"))?;
    if n == 0 {
        return Err("the number of modes must be at least 1 (or auto)".into());
    }
    Ok(ModeSelection::Count(n))
}

/// Parses the iteration method: `riv` (refined instrumental variables) or `sk`.
pub fn parse_method(s: &str) -> Result<IvMethod, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "riv" => Ok(IvMethod::Riv),
        "sk" => Ok(IvMethod::Sk),
        _ => Err(format!("expected riv or sk, got `{s}`")),
    }
}

/// Parses the weighting: `auto`, `variance`, `magnitude` or `uniform`.
pub fn parse_weighting(s: &str) -> Result<Weighting, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "auto" => Ok(Weighting::Auto),
        "variance" => Ok(Weighting::InverseVariance),
        "magnitude" => Ok(Weighting::InverseMagnitude),
        "uniform" => Ok(Weighting::Uniform),
        _ => Err(format!(
            "expected auto, variance, magnitude or uniform, got `{s}`"
        )),
    }
}

/// Parses what the FRF measures: `displacement`, `velocity` or `accelerance`.
pub fn parse_frf_type(s: &str) -> Result<FrfType, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "displacement" => Ok(FrfType::Displacement),
        "velocity" => Ok(FrfType::Velocity),
        "accelerance" | "acceleration" => Ok(FrfType::Accelerance),
        _ => Err(format!(
            "expected displacement, velocity or accelerance, got `{s}`"
        )),
    }
}

/// The options of `fit` and `diagnose`, as every front end gives them. Defaults are
/// those of the command line (`FitSpec::default()`: the whole data, every CMIF peak, the
/// hold and delay the file declares, refined IV, `auto` weighting, the default chain).
#[derive(Debug, Clone, Default)]
pub struct FitSpec {
    /// Band to fit. Default: every line.
    pub band: Option<Band>,
    /// Delay handling. Default: `auto` for fit, the declared delay for diagnose.
    pub delay: Option<DelayChoice>,
    /// Hold. Default: what the file declares.
    pub hold: Option<Hold>,
    /// Modes to start from. Default: every CMIF peak.
    pub modes: Option<ModeSelection>,
    /// Refined IV or SK. Default: refined IV.
    pub method: IvMethod,
    /// Initialiser(s) of the chain; empty: by the size of the data.
    pub init: String,
    /// Refiner of the chain; empty: by the size of the data.
    pub refine: String,
    /// Model order for the initialisers that take one. Default: from the data.
    pub order: Option<usize>,
    /// Multi-band SK cut-offs (`--init sk` only). Default: one band.
    pub bands: Option<BandSpec>,
    /// Tiered weights of the multi-band fit. Default: `0.1, 1e-4`.
    pub band_weights: Option<(f64, f64)>,
    /// Weighting of the criterion. Default: `auto`.
    pub weighting: Weighting,
    /// What the FRF measures. Default: displacement.
    pub frf_type: FrfType,
    /// Sample rate of the measurement to test a hold at (diagnose), Hz. Default: from the
    /// file's comments.
    pub fs_hz: Option<f64>,
}

impl FitSpec {
    /// The pipeline configuration these options describe (no diagnosis, no progress).
    pub fn pipeline_config(&self) -> PipelineConfig {
        PipelineConfig {
            band_hz: self.band.map(|b| b.as_range()),
            modes: self.modes.clone().unwrap_or_default(),
            hold: self.hold,
            delay: self.delay,
            fs_hz: self.fs_hz,
            method: self.method,
            weighting: self.weighting.clone(),
            init: self.init.clone(),
            refine: self.refine.clone(),
            order: self.order,
            sk_bands: self.bands.clone().map(|spec| {
                let d = SkBands::default();
                let (q_low, q_high) = self.band_weights.unwrap_or((d.q_low, d.q_high));
                SkBands {
                    spec,
                    q_low,
                    q_high,
                }
            }),
            frf_type: self.frf_type,
            ..Default::default()
        }
    }

    /// Checks the options against the data before a fit: a weighting by the variance
    /// needs `_var` columns; a sample rate must be positive; a multi-band fit needs
    /// `init = "sk"`; band weights need bands.
    pub fn check(&self, data: &Frf) -> Result<(), FrfitError> {
        if self.weighting == Weighting::InverseVariance && !data.has_variance() {
            return Err(FrfitError::argument(
                "--weighting",
                "variance",
                "the data carry no `_var` columns; use auto, magnitude or uniform",
            ));
        }
        if let Some(fs) = self.fs_hz {
            if !(fs.is_finite() && fs > 0.0) {
                return Err(FrfitError::argument(
                    "--fs",
                    fs,
                    "must be a sample rate > 0 Hz",
                ));
            }
        }
        if self.band_weights.is_some() && self.bands.is_none() {
            return Err(FrfitError::argument(
                "--band-weights",
                format!("{:?}", self.band_weights.unwrap_or_default()),
                "band weights need --bands (the multi-band SK fit)",
            ));
        }
        if let Some(0) = self.order {
            return Err(FrfitError::argument(
                "--order",
                0,
                "a model order is at least 1 state",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_parsing() {
        assert_eq!(
            parse_band("20:2000").unwrap(),
            Band {
                lo_hz: Some(20.0),
                hi_hz: Some(2000.0)
            }
        );
        assert_eq!(parse_band("20:").unwrap().hi_hz, None);
        assert_eq!(parse_band(":5").unwrap().lo_hz, None);
        assert!(parse_band("20").is_err());
        assert!(parse_band("30:20").is_err());
        assert!(parse_band("a:20").unwrap_err().contains("not a number"));
        assert!(parse_band("-1:20").is_err());
        assert!(Band::new(Some(30.0), Some(20.0)).is_err());
        assert!(Band::new(Some(f64::NAN), None).is_err());
        assert_eq!(Band::new(None, Some(5.0)).unwrap().as_range(), (0.0, 5.0));
    }

    #[test]
    fn option_words() {
        assert_eq!(parse_hold("zoh:10000"), Ok(Hold::Zoh { fs_hz: 1e4 }));
        assert_eq!(parse_hold(" NONE "), Ok(Hold::None));
        assert!(parse_hold("zoh:-1").unwrap_err().contains("> 0"));
        assert!(parse_hold("foh:100").unwrap_err().contains("unknown hold"));
        assert_eq!(
            parse_delay("150us"),
            Ok(DelayChoice::Fixed { seconds: 150e-6 })
        );
        assert_eq!(parse_delay("auto"), Ok(DelayChoice::Auto));
        assert!(parse_delay("-1").is_err());
        assert_eq!(parse_modes("17"), Ok(ModeSelection::Count(17)));
        assert!(parse_modes("0").is_err());
        assert_eq!(parse_method("SK"), Ok(IvMethod::Sk));
        assert!(parse_method("ml").is_err());
        assert_eq!(parse_weighting("variance"), Ok(Weighting::InverseVariance));
        assert!(parse_weighting("x").unwrap_err().contains("uniform"));
        assert_eq!(parse_frf_type("accelerance"), Ok(FrfType::Accelerance));
        assert_eq!(parse_band_weights("0.1,1e-4"), Ok((0.1, 1e-4)));
        assert!(parse_band_weights("2,1").is_err());
        assert_eq!(fmt_num(0.25), "0.25");
        assert_eq!(fmt_num(1.5e-7), "1.5e-7");
    }

    #[test]
    fn spec_checks_name_the_option() {
        let data = Frf::new(
            vec![1.0, 2.0],
            1,
            1,
            vec![frf_data::C64::new(1.0, 0.0); 2],
            None,
        )
        .unwrap();
        let spec = FitSpec {
            weighting: Weighting::InverseVariance,
            ..Default::default()
        };
        assert!(spec.check(&data).unwrap_err().to_string().contains("_var"));
        let spec = FitSpec {
            band_weights: Some((0.1, 0.1)),
            ..Default::default()
        };
        assert!(spec
            .check(&data)
            .unwrap_err()
            .to_string()
            .contains("--bands"));
        assert!(FitSpec::default().check(&data).is_ok());
        let cfg = FitSpec {
            band: Some(Band::new(Some(20.0), None).unwrap()),
            ..Default::default()
        }
        .pipeline_config();
        assert_eq!(cfg.band_hz, Some((20.0, f64::MAX)));
    }
}
