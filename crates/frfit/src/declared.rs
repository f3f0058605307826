//! What a data file declares about its measurement: the sample rate and the known
//! (hold + computation) delay, from `key=value` / `key: value` metadata or from comment
//! lines such as `# sampling 10 kHz; hold and computation delay ~150 us present: True`.
//! A declared effect is part of the model from the start, not a discovery of the
//! diagnosis loop.

use frf_data::Frf;

/// Declarations found in a file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Declared {
    /// Sample rate, Hz.
    pub fs_hz: Option<f64>,
    /// The known delay (hold + computation), seconds.
    pub delay_s: Option<f64>,
    /// The file says the measurement went through a zero-order hold (at `fs_hz`):
    /// a comment that names a "hold" and says it is present ("present: True",
    /// "hold present") and not absent ("False", "no hold").
    pub zoh: bool,
    /// Realizations the variance was estimated from ("10 periods x 10 realizations", or
    /// metadata `realizations`): it sets the degrees of freedom of the variance.
    pub realizations: Option<usize>,
    /// Periods per realization the variance was estimated over (the comment word
    /// `periods=P` of `frfit nonparametric`, or metadata `periods`).
    pub periods: Option<usize>,
    /// Where each value came from (for reports).
    pub sources: Vec<String>,
}

/// Unit multiplier of a frequency unit word.
fn hz_unit(word: &str) -> Option<f64> {
    match word
        .trim_matches(|c: char| !c.is_alphanumeric())
        .to_ascii_lowercase()
        .as_str()
    {
        "hz" => Some(1.0),
        "khz" => Some(1e3),
        "mhz" => Some(1e6),
        _ => None,
    }
}

/// Unit multiplier of a time unit word.
fn s_unit(word: &str) -> Option<f64> {
    match word
        .trim_matches(|c: char| !c.is_alphanumeric())
        .to_ascii_lowercase()
        .as_str()
    {
        "s" | "sec" => Some(1.0),
        "ms" => Some(1e-3),
        "us" | "µs" | "usec" => Some(1e-6),
        "ns" => Some(1e-9),
        _ => None,
    }
}

fn number(word: &str) -> Option<f64> {
    let w = word
        .trim_start_matches(['~', '=', '('])
        .trim_end_matches([',', ';', ')', ':']);
    w.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0)
}

/// `<keyword> [~|=] <number> <unit>` anywhere in `text`: the first number after the
/// keyword that is followed by a unit `unit` accepts.
fn after_keyword(text: &str, keyword: &str, unit: fn(&str) -> Option<f64>) -> Option<f64> {
    let lower = text.to_ascii_lowercase();
    let pos = lower.find(keyword)?;
    let words: Vec<&str> = text[pos + keyword.len()..]
        .split_whitespace()
        .take(6)
        .collect();
    for w in 0..words.len() {
        if let Some(v) = number(words[w]) {
            // "10 kHz" or "10kHz"
            if let Some(u) = words.get(w + 1).and_then(|u| unit(u)) {
                return Some(v * u);
            }
        }
        let t = words[w].trim_start_matches(['~', '=']);
        let split = t.find(|c: char| c.is_ascii_alphabetic() || c == 'µ');
        if let Some(i) = split {
            if let (Some(v), Some(u)) = (number(&t[..i]), unit(&t[i..])) {
                return Some(v * u);
            }
        }
    }
    None
}

/// Reads the declarations of `frf`: metadata keys `fs`, `fs_hz`, `sample_rate`,
/// `sampling` (Hz or with a unit), `delay_s`, `delay_us`, `delay`; then comment lines
/// with "sampling <n> <Hz|kHz>" and "delay ~<n> <s|ms|us>".
pub fn declared(frf: &Frf) -> Declared {
    let mut d = Declared::default();
    for (k, v) in &frf.metadata {
        let key = k.to_ascii_lowercase();
        let val = v.trim();
        let first = val.split_whitespace().next().unwrap_or("");
        let with_unit = |unit: fn(&str) -> Option<f64>| -> Option<f64> {
            let mut it = val.split_whitespace();
            let x = number(it.next()?)?;
            Some(x * it.next().and_then(unit).unwrap_or(1.0))
        };
        match key.as_str() {
            "fs" | "fs_hz" | "sample_rate" | "sample_rate_hz" | "sampling" | "sampling_hz"
                if d.fs_hz.is_none() =>
            {
                if let Some(x) = with_unit(hz_unit) {
                    d.fs_hz = Some(x);
                    d.sources
                        .push(format!("sample rate {x} Hz from metadata `{k}`"));
                }
            }
            "delay_s" | "delay" if d.delay_s.is_none() => {
                if let Some(x) = with_unit(s_unit) {
                    d.delay_s = Some(x);
                    d.sources
                        .push(format!("delay {:.1} us from metadata `{k}`", x * 1e6));
                }
            }
            "delay_us" if d.delay_s.is_none() => {
                if let Some(x) = number(first) {
                    d.delay_s = Some(x * 1e-6);
                    d.sources.push(format!("delay {x} us from metadata `{k}`"));
                }
            }
            _ => {}
        }
    }
    if let Some(r) = frf
        .metadata
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case("realizations"))
        .and_then(|(_, v)| v.trim().parse::<usize>().ok())
    {
        d.realizations = Some(r);
        d.sources
            .push(format!("{r} realizations from metadata `realizations`"));
    }
    if let Some(p) = frf
        .metadata
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case("periods"))
        .and_then(|(_, v)| v.trim().parse::<usize>().ok())
    {
        d.periods = Some(p);
    }
    for c in &frf.comments {
        let lower = c.to_ascii_lowercase();
        // the words `periods=P realizations=R` of `frfit nonparametric` (FORMATS.md)
        for w in lower.split(|ch: char| ch.is_whitespace() || ch == ',' || ch == ';') {
            let value = |key: &str| w.strip_prefix(key).and_then(|v| v.parse::<usize>().ok());
            if let (Some(r), None) = (value("realizations="), d.realizations) {
                d.realizations = Some(r);
                d.sources.push(format!(
                    "{r} realizations from the comment \"{}\"",
                    c.trim()
                ));
            }
            if let (Some(p), None) = (value("periods="), d.periods) {
                d.periods = Some(p);
            }
        }
        if d.realizations.is_none() {
            // "<n> realizations": the number right before the word
            let words: Vec<&str> = lower
                .split(|ch: char| ch.is_whitespace() || ch == ',' || ch == ';')
                .filter(|w| !w.is_empty())
                .collect();
            if let Some(i) = words.iter().position(|w| w.starts_with("realization")) {
                if let Some(r) = i
                    .checked_sub(1)
                    .and_then(|j| words[j].parse::<usize>().ok())
                {
                    d.realizations = Some(r);
                    d.sources.push(format!(
                        "{r} realizations from the comment \"{}\"",
                        c.trim()
                    ));
                }
            }
        }
        if lower.contains("hold") && !d.zoh {
            let absent = lower.contains("false")
                || lower.contains("no hold")
                || lower.contains("without hold");
            let present = lower.contains("true")
                || lower.contains("present")
                || lower.contains("zero-order hold");
            if present && !absent {
                d.zoh = true;
                d.sources
                    .push(format!("zero-order hold from the comment \"{}\"", c.trim()));
            }
        }
        if d.fs_hz.is_none() {
            if let Some(x) = after_keyword(c, "sampling", hz_unit)
                .or_else(|| after_keyword(c, "sample rate", hz_unit))
            {
                d.fs_hz = Some(x);
                d.sources.push(format!(
                    "sample rate {x} Hz from the comment \"{}\"",
                    c.trim()
                ));
            }
        }
        if d.delay_s.is_none() {
            if let Some(x) = after_keyword(c, "delay", s_unit) {
                d.delay_s = Some(x);
                d.sources.push(format!(
                    "delay {:.1} us from the comment \"{}\"",
                    x * 1e6,
                    c.trim()
                ));
            }
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use frf_data::C64;

    fn frf_with(comments: &[&str], meta: &[(&str, &str)]) -> Frf {
        let mut f = Frf::new(vec![1.0, 2.0], 1, 1, vec![C64::new(1.0, 0.0); 2], None).unwrap();
        f.comments = comments.iter().map(|s| s.to_string()).collect();
        for (k, v) in meta {
            f.metadata.insert(k.to_string(), v.to_string());
        }
        f
    }

    #[test]
    fn wafer_comment_line() {
        let f = frf_with(
            &[" sampling 10 kHz; hold and computation delay ~150 us present: True"],
            &[],
        );
        let d = declared(&f);
        assert_eq!(d.fs_hz, Some(10_000.0));
        assert!((d.delay_s.unwrap() - 150e-6).abs() < 1e-12);
        assert!(d.zoh);
        assert_eq!(d.sources.len(), 3);
        let f = frf_with(
            &["sampling 10 kHz; hold and computation delay ~150 us present: False"],
            &[],
        );
        assert!(!declared(&f).zoh);
    }

    #[test]
    fn metadata_keys_and_units() {
        let d = declared(&frf_with(&[], &[("fs", "2500"), ("delay_us", "60")]));
        assert_eq!(d.fs_hz, Some(2500.0));
        assert!((d.delay_s.unwrap() - 60e-6).abs() < 1e-15);
        let d = declared(&frf_with(
            &["sample rate: 1.024 kHz"],
            &[("delay", "0.5 ms")],
        ));
        assert!((d.fs_hz.unwrap() - 1024.0).abs() < 1e-9);
        assert!((d.delay_s.unwrap() - 5e-4).abs() < 1e-15);
    }

    #[test]
    fn nothing_declared() {
        let d = declared(&frf_with(
            &["an accelerance measurement", "delay unknown"],
            &[("units", "m/N")],
        ));
        assert_eq!(d, Declared::default());
    }
}
