//! `cargo xtask fuzz READER --runs N`: coverage-guided fuzzing of one reader with
//! libFuzzer through `cargo fuzz` on the stable toolchain (`RUSTC_BOOTSTRAP=1`, no
//! sanitizer: the readers hold no unsafe code). The fuzz crate (`fuzz/`) is outside
//! the workspace.
//!
//! The corpus `fuzz/corpus/READER` is seeded (when empty) with small files made from
//! the reference data in `../shared/data` (a few lines of each, in the variants the
//! reader accepts) and from synthetic data; crashes go to `fuzz/artifacts/READER`.
//! Each run is bounded: no input may take more than `--timeout` seconds, and the target
//! fails when a reader allocates more than 10x its input (plus 1 MiB).

use crate::{Context, Error};
use clap::{Args as ClapArgs, ValueEnum};
use frf_data::io::{frf_csv_string, frf_mat_bytes, read_frf, read_uff58, uff58_bytes, UffEncoding};
use frf_data::shared_data::shared_data_dir;
use frf_data::{Frf, FrfDataset, C64};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The readers that have a fuzz target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Reader {
    /// FRF CSV, every dialect.
    Csv,
    /// UFF dataset 58, ASCII and binary.
    Uff,
    /// Periodic spectra CSV.
    Spectra,
    /// MATLAB level-5 .mat (time records and FRF).
    Mat,
    /// Model JSON.
    ModelJson,
}

impl Reader {
    fn target(self) -> &'static str {
        match self {
            Reader::Csv => "csv",
            Reader::Uff => "uff",
            Reader::Spectra => "spectra",
            Reader::Mat => "mat",
            Reader::ModelJson => "model_json",
        }
    }
}

/// Arguments of `cargo xtask fuzz`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// The reader to fuzz.
    #[arg(value_enum)]
    pub reader: Reader,
    /// Number of executions (libFuzzer's -runs).
    #[arg(long, default_value_t = 1_000_000)]
    pub runs: u64,
    /// Longest input, bytes (libFuzzer's -max_len).
    #[arg(long, default_value_t = 16_384)]
    pub max_len: usize,
    /// An input that takes longer than this many seconds is a finding (a hang).
    #[arg(long, default_value_t = 1)]
    pub timeout: u32,
    /// Write the seed corpus and stop.
    #[arg(long)]
    pub seed_only: bool,
}

/// The workspace root (xtask's manifest directory is `<root>/xtask`).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// The first `n` lines and up to `m x m` entries of `d`.
fn head(d: &Frf, n: usize, m: usize) -> Option<Frf> {
    let n = n.min(d.n_lines());
    let (ny, nu) = (d.ny().min(m), d.nu().min(m));
    let f = d.freq_hz_slice()[..n].to_vec();
    let full_ny = d.ny();
    let mut out = Frf::from_fn(f, ny, nu, |k, i, j| d.line(k)[j * full_ny + i]).ok()?;
    if let Some(v) = d.variances() {
        let m_all = d.ny() * d.nu();
        let var: Vec<f64> = (0..n)
            .flat_map(|k| {
                (0..nu).flat_map(move |j| (0..ny).map(move |i| v[k * m_all + j * full_ny + i]))
            })
            .collect();
        out = out.with_variance(Some(var)).ok()?;
    }
    out.units = d.units.clone();
    Some(out)
}

/// A spreadsheet's rendering of a plain FRF CSV: `;` separators, `,` decimals, quoted
/// header, CRLF, byte-order mark.
fn excel(text: &str) -> String {
    let body: Vec<String> = text
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                l.to_string()
            } else if l.starts_with("freq_hz") {
                l.split(',')
                    .map(|x| format!("\"{x}\""))
                    .collect::<Vec<_>>()
                    .join(";")
            } else {
                l.replace(',', ";").replace('.', ",")
            }
        })
        .collect();
    format!("\u{feff}{}\r\n", body.join("\r\n"))
}

fn synthetic() -> Frf {
    let mut f = Frf::from_fn(vec![0.5, 1.0, 1.5, 2.5], 2, 2, |k, i, j| {
        C64::new(1.0 / (1.0 + k as f64) - i as f64, 1e-3 * j as f64 - 0.25)
    })
    .unwrap_or_else(|e| panic!("synthetic seed: {e}"));
    f.units = Some("m/N".into());
    f
}

/// The small FRFs every FRF reader's seeds are made of.
fn frf_seeds(shared: Option<&Path>) -> Vec<(String, Frf)> {
    let mut out = vec![("synthetic".to_string(), synthetic())];
    if let Some(dir) = shared {
        for name in [
            "wafer_nominal.csv",
            "wafer_hidden_mode.csv",
            "real/daisy_flexible_structure.csv",
            "real/ladisk_beam_accelerance.csv",
            "real/fditools_motorbench_msA.csv",
        ] {
            if let Some(h) = read_frf(dir.join(name)).ok().and_then(|d| head(&d, 5, 2)) {
                out.push((name.replace(['/', '.'], "_"), h));
            }
        }
    }
    out
}

/// A MAT-file holding only the top-level elements of `bytes` smaller than `max` bytes
/// (the scalars, objects and their subsystem data of a real file, without its long
/// records).
fn small_elements(bytes: &[u8], max: usize) -> Option<Vec<u8>> {
    let mut out = bytes.get(..128)?.to_vec();
    let little = bytes.get(126..128)? == b"IM";
    let u32_at = |p: usize| -> Option<usize> {
        let b: [u8; 4] = bytes.get(p..p + 4)?.try_into().ok()?;
        Some(if little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        } as usize)
    };
    let mut pos = 128;
    while pos + 8 <= bytes.len() {
        let ty = u32_at(pos)?;
        let size = u32_at(pos + 4)?;
        let end = (pos + 8 + if ty == 15 { size } else { size.div_ceil(8) * 8 }).min(bytes.len());
        if size < max {
            out.extend_from_slice(&bytes[pos..end]);
        }
        pos = end;
    }
    Some(out)
}

/// `file` with each variable wrapped in an miCOMPRESSED element (as MATLAB's -v7 does).
fn compressed(file: &[u8]) -> Vec<u8> {
    let mut out = file[..128].to_vec();
    let mut pos = 128;
    while pos + 8 <= file.len() {
        let size = u32::from_le_bytes([file[pos + 4], file[pos + 5], file[pos + 6], file[pos + 7]])
            as usize;
        let end = (pos + 8 + size.div_ceil(8) * 8).min(file.len());
        let z = miniz_oxide::deflate::compress_to_vec_zlib(&file[pos..end], 6);
        out.extend_from_slice(&15u32.to_le_bytes());
        out.extend_from_slice(&(z.len() as u32).to_le_bytes());
        out.extend_from_slice(&z);
        pos = end;
    }
    out
}

fn model_json_seeds() -> Result<Vec<(String, Vec<u8>)>, Error> {
    use frfit::additive_riv::{AdditiveModel, Domain, ModelFile, Provenance};
    let mut out = Vec::new();
    for (ny, nu, modes) in [(1, 1, 1), (2, 3, 2)] {
        let mut m = AdditiveModel::new(ny, nu, Domain::Continuous).stage("model seed")?;
        for q in 0..modes {
            m.push_mode(10.0 * (q + 1) as f64, 0.02, false)
                .stage("model seed")?;
        }
        let f = ModelFile::from_model(
            &m,
            Some("m/N".into()),
            Some((1.0, 100.0)),
            Provenance::default(),
        )
        .stage("model seed")?;
        let text = serde_json::to_string_pretty(&f).stage("model seed")?;
        out.push((format!("model_{ny}x{nu}.json"), text.into_bytes()));
    }
    Ok(out)
}

/// The seed files of `reader`: (file name, bytes).
fn seeds(reader: Reader, shared: Option<&Path>) -> Result<Vec<(String, Vec<u8>)>, Error> {
    let mut out: Vec<(String, Vec<u8>)> = Vec::new();
    match reader {
        Reader::Csv => {
            for (name, f) in frf_seeds(shared) {
                let plain = frf_csv_string(&f, &[]);
                out.push((format!("{name}.excel.csv"), excel(&plain).into_bytes()));
                out.push((format!("{name}.csv"), plain.into_bytes()));
            }
        }
        Reader::Uff => {
            let mut frfs = frf_seeds(shared);
            if let Some(h) = shared
                .and_then(|d| read_uff58(d.join("uff/wafer_nominal.uff")).ok())
                .and_then(|d| {
                    let mut h = head(&d, 5, 2)?;
                    h.metadata = d.metadata.clone();
                    Some(h)
                })
            {
                frfs.push(("wafer_nominal_uff".into(), h));
            }
            let other = b"    -1\n   151\nmodel\ndescription\napp\n  01-JAN-26\n    -1\n    -1\n   164\n         1  SI\n    -1\n";
            for (name, f) in frfs {
                for (tag, enc) in [
                    ("ascii", UffEncoding::Ascii),
                    (
                        "le64",
                        UffEncoding::Binary {
                            little_endian: true,
                            double: true,
                        },
                    ),
                    (
                        "be32",
                        UffEncoding::Binary {
                            little_endian: false,
                            double: false,
                        },
                    ),
                ] {
                    if let Ok(b) = uff58_bytes(&f, &f.metadata, enc) {
                        let mut with_other = other.to_vec();
                        with_other.extend_from_slice(&b);
                        out.push((format!("{name}.{tag}.uff"), b));
                        out.push((format!("{name}.{tag}.other.uff"), with_other));
                    }
                }
            }
        }
        Reader::Spectra => {
            if let Some(text) = shared.and_then(|d| {
                std::fs::read_to_string(d.join("real/fditools_motorbench_msA.periods.csv")).ok()
            }) {
                let head: String = text.lines().take(14).map(|l| format!("{l}\n")).collect();
                out.push(("motorbench_periods_head.csv".into(), head.into_bytes()));
            }
            out.push((
                "synthetic_periods.csv".into(),
                b"# ny=1 nu=1 experiments=1 realizations=1 periods=2\n\
                  freq_hz,experiment,realization,period,U1_re,U1_im,Y1_re,Y1_im\n\
                  1,1,1,1,1,0,0.5,-0.5\n1,1,1,2,1,0,0.5,-0.25\n\
                  2,1,1,1,1,0,0.25,-0.5\n2,1,1,2,1,0,0.25,-0.5\n"
                    .to_vec(),
            ));
        }
        Reader::Mat => {
            for (name, f) in frf_seeds(shared).into_iter().take(3) {
                let plain = frf_mat_bytes(&f);
                out.push((format!("{name}.z.mat"), compressed(&plain)));
                out.push((format!("{name}.mat"), plain));
            }
            if let Some(b) = shared
                .and_then(|d| std::fs::read(d.join("real/fditools_motorbench_msA.mat")).ok())
                .and_then(|b| small_elements(&b, 16_384))
            {
                out.push(("motorbench_small_elements.mat".into(), b));
            }
        }
        Reader::ModelJson => out.extend(model_json_seeds()?),
    }
    Ok(out)
}

/// Runs `cargo xtask fuzz`.
pub fn run(args: Args) -> Result<(), Error> {
    let root = root();
    let target = args.reader.target();
    let corpus = root.join("fuzz").join("corpus").join(target);
    let artifacts = root.join("fuzz").join("artifacts").join(target);
    std::fs::create_dir_all(&corpus).stage("corpus directory")?;
    std::fs::create_dir_all(&artifacts).stage("artifacts directory")?;
    let shared = shared_data_dir();
    if shared.is_none() {
        eprintln!("note: ../shared/data not found; seeding from synthetic data only");
    }
    let empty = std::fs::read_dir(&corpus)
        .stage("corpus directory")?
        .next()
        .is_none();
    if empty {
        let s = seeds(args.reader, shared.as_deref())?;
        for (name, bytes) in &s {
            std::fs::write(corpus.join(name), bytes).stage("seed corpus")?;
        }
        eprintln!("seeded {} with {} files", corpus.display(), s.len());
    }
    if args.seed_only {
        return Ok(());
    }
    let ok = Command::new("cargo")
        .args(["fuzz", "--version"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        return Err(Error::new(
            "cargo fuzz",
            "cargo-fuzz is not installed: run `cargo install cargo-fuzz` (a C++ compiler is \
             needed to build libFuzzer)",
        ));
    }
    let status = Command::new("cargo")
        .current_dir(&root)
        .env("RUSTC_BOOTSTRAP", "1")
        .env_remove("CARGO_TARGET_DIR")
        .args(["fuzz", "run", "--sanitizer", "none", target])
        .arg(&corpus)
        .arg("--")
        .arg(format!("-runs={}", args.runs))
        .arg(format!("-max_len={}", args.max_len))
        .arg(format!("-timeout={}", args.timeout))
        .arg("-rss_limit_mb=2048")
        .arg("-print_final_stats=1")
        .arg(format!("-artifact_prefix={}/", artifacts.display()))
        .status()
        .stage("cargo fuzz run")?;
    if status.success() {
        eprintln!(
            "fuzz {target}: {} executions, no finding (corpus {})",
            args.runs,
            corpus.display()
        );
        Ok(())
    } else {
        Err(Error::new(
            "cargo fuzz run",
            format!(
                "{target}: libFuzzer stopped with {status}: a finding is in {}",
                artifacts.display()
            ),
        ))
    }
}
