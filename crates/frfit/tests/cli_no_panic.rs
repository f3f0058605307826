//! No input makes a `frfit` command exit by a panic (exit code 101): the binary runs on
//! a deterministic corpus of mutated files (bit flips, truncations, duplicated and
//! deleted chunks, byte runs, huge length fields) made here from small valid files of
//! every format it reads: FRF CSV (plain and spreadsheet dialect), UFF 58 (ASCII and
//! binary), MATLAB .mat (FRF and time records, plain and compressed), periodic spectra
//! CSV and model JSON.

mod common;

use common::{run, stderr, temp_dir};
use frf_data::io::mat5::{mat5_bytes, MatWrite};
use frf_data::io::{frf_csv_string, frf_mat_bytes, uff58_bytes, UffEncoding};
use frf_data::{Frf, C64};
use std::path::Path;

/// xorshift64*: deterministic mutations.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn mutate(b: &[u8], rng: &mut Rng, kind: usize) -> Vec<u8> {
    let mut b = b.to_vec();
    let len = b.len();
    if len < 16 {
        return b;
    }
    match kind % 7 {
        0 => {
            for _ in 0..1 + rng.below(6) {
                let i = rng.below(len);
                b[i] ^= 1 << rng.below(8);
            }
        }
        1 => b.truncate(rng.below(len)),
        2 => {
            let i = rng.below(len);
            let k = rng.below(80).min(len - i);
            let chunk = b[i..i + k].to_vec();
            let at = rng.below(len);
            b.splice(at..at, chunk);
        }
        3 => {
            let i = rng.below(len);
            let k = rng.below(120).min(len - i);
            b.drain(i..i + k);
        }
        4 => {
            let i = rng.below(len - 4);
            let v = [0xffff_fff0u32, 0x7fff_ffff, 0x0001_0000, 15, 14][rng.below(5)];
            b[i..i + 4].copy_from_slice(&v.to_le_bytes());
        }
        5 => {
            // A huge or odd number in text.
            let i = rng.below(len);
            let s = [
                "9e999",
                "-0",
                "1e-320",
                "99999999999",
                "NaN",
                ";",
                "\"",
                "\r",
                "-1\n58b\n",
            ][rng.below(9)];
            b.splice(i..i, s.bytes());
        }
        _ => {
            let i = rng.below(len);
            let k = rng.below(24).min(len - i);
            let x = rng.next() as u8;
            b[i..i + k].iter_mut().for_each(|y| *y = x);
        }
    }
    b
}

fn small_frf() -> Frf {
    let mut f = Frf::from_fn(vec![1.0, 2.0, 3.0, 4.5, 6.0], 2, 2, |k, i, j| {
        C64::new(1.0 / (1.0 + k as f64) + i as f64, 0.1 * j as f64 - 0.3)
    })
    .unwrap()
    .with_variance(Some((0..20).map(|q| 1e-4 * (q + 1) as f64).collect()))
    .unwrap();
    f.units = Some("m/N".into());
    f
}

/// Wraps each top-level element of a MAT-file in an miCOMPRESSED element.
fn compressed(file: &[u8]) -> Vec<u8> {
    let mut out = file[..128].to_vec();
    let mut pos = 128;
    while pos + 8 <= file.len() {
        let size = u32::from_le_bytes(file[pos + 4..pos + 8].try_into().unwrap()) as usize;
        let end = (pos + 8 + size.div_ceil(8) * 8).min(file.len());
        let z = miniz_oxide::deflate::compress_to_vec_zlib(&file[pos..end], 6);
        out.extend_from_slice(&15u32.to_le_bytes());
        out.extend_from_slice(&(z.len() as u32).to_le_bytes());
        out.extend_from_slice(&z);
        pos = end;
    }
    out
}

/// A periodic time record: `u` a two-tone multisine, `y` a filtered copy, 4 periods of 64
/// samples at 64 Hz.
fn time_record_mat() -> Vec<u8> {
    let (n, p) = (64usize, 4usize);
    let u: Vec<f64> = (0..n * p)
        .map(|t| {
            let x = t as f64 / n as f64 * std::f64::consts::TAU;
            (3.0 * x).sin() + (5.0 * x + 1.0).sin()
        })
        .collect();
    let y: Vec<f64> = (0..n * p)
        .map(|t| 0.5 * u[t] + 0.25 * u[(t + n * p - 1) % (n * p)])
        .collect();
    mat5_bytes(&[
        MatWrite {
            name: "u",
            dims: &[n * p, 1],
            real: &u,
            imag: None,
        },
        MatWrite {
            name: "y",
            dims: &[n * p, 1],
            real: &y,
            imag: None,
        },
        MatWrite {
            name: "fs",
            dims: &[1, 1],
            real: &[64.0],
            imag: None,
        },
    ])
}

const SPECTRA: &str = "# ny=1 nu=1 experiments=1 realizations=1 periods=3\n\
freq_hz,experiment,realization,period,U1_re,U1_im,Y1_re,Y1_im\n\
1,1,1,1,1,0,0.5,-0.5\n1,1,1,2,1,0,0.5,-0.25\n1,1,1,3,1,0,0.5,-0.4\n\
2,1,1,1,1,0,0.25,-0.5\n2,1,1,2,1,0,0.25,-0.5\n2,1,1,3,1,0,0.25,-0.45\n";

/// Runs `args` and fails the test on a panic exit.
#[track_caller]
fn no_panic(args: &[&str], file: &Path, runs: &mut usize) {
    let o = run(args);
    *runs += 1;
    let code = o.status.code();
    let e = stderr(&o);
    assert!(
        code != Some(101) && !e.contains("panicked"),
        "frfit {} panicked on {} (a copy is kept there):\n{e}",
        args.join(" "),
        file.display()
    );
    // No signal either (an abort from an allocation failure, a stack overflow).
    assert!(
        code.is_some(),
        "frfit {} was killed: {:?}",
        args.join(" "),
        o.status
    );
}

#[test]
fn no_mutated_input_makes_frfit_panic() {
    let dir = temp_dir("no-panic");
    let f = small_frf();
    let plain_csv = frf_csv_string(&f, &[]);
    let excel: String = plain_csv
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                format!("{l}\r\n")
            } else {
                format!("{}\r\n", l.replace(',', ";").replace('.', ","))
            }
        })
        .collect();
    let mat = frf_mat_bytes(&f);
    let sources: Vec<(&str, Vec<u8>)> = vec![
        ("csv", plain_csv.clone().into_bytes()),
        ("csv", format!("\u{feff}{excel}").into_bytes()),
        (
            "uff",
            uff58_bytes(&f, &f.metadata, UffEncoding::Ascii).unwrap(),
        ),
        (
            "uff",
            uff58_bytes(
                &f,
                &f.metadata,
                UffEncoding::Binary {
                    little_endian: false,
                    double: false,
                },
            )
            .unwrap(),
        ),
        ("mat", compressed(&mat)),
        ("mat", mat),
        ("time.mat", compressed(&time_record_mat())),
        ("spectra.csv", SPECTRA.as_bytes().to_vec()),
    ];
    // The originals work.
    let plant = dir.join("plant.csv");
    std::fs::write(&plant, &plain_csv).unwrap();
    let plant_s = plant.to_str().unwrap();
    let out = dir.join("out.csv");
    let out_s = out.to_str().unwrap();
    let mut rng = Rng(0x00c0_ffee);
    let mut runs = 0;
    let mut errors = 0;
    for (q, (kind, bytes)) in sources.iter().enumerate() {
        for m in 0..40 {
            let data = if m == 0 {
                bytes.clone()
            } else {
                mutate(bytes, &mut rng, m)
            };
            let ext = if kind.ends_with("csv") {
                "csv"
            } else {
                kind.rsplit('.').next().unwrap()
            };
            let path = dir.join(format!("in{q}_{m}.{ext}"));
            std::fs::write(&path, &data).unwrap();
            let p = path.to_str().unwrap();
            match *kind {
                "time.mat" => {
                    let args = [
                        "--quiet",
                        "nonparametric",
                        p,
                        "--input",
                        "u",
                        "--output",
                        "y",
                        "--period",
                        "64",
                        "--out",
                        out_s,
                    ];
                    no_panic(&args, &path, &mut runs);
                }
                "spectra.csv" => {
                    no_panic(
                        &["--quiet", "nonparametric", p, "--out", out_s],
                        &path,
                        &mut runs,
                    );
                }
                _ => {
                    let o = run(&["info", p]);
                    runs += 1;
                    assert_ne!(o.status.code(), Some(101), "info {p}: {}", stderr(&o));
                    if !o.status.success() {
                        errors += 1;
                        // The error names the file.
                        assert!(stderr(&o).contains(p), "{}", stderr(&o));
                    }
                    if m == 0 {
                        assert!(o.status.success(), "the original {p}: {}", stderr(&o));
                    }
                    let conv = dir.join(format!("conv{q}_{m}.mat"));
                    no_panic(
                        &["--quiet", "convert", p, conv.to_str().unwrap()],
                        &path,
                        &mut runs,
                    );
                    no_panic(&["cmif", p], &path, &mut runs);
                }
            }
            let _ = std::fs::remove_file(&path);
        }
    }
    // A mutated model JSON through `eval` (the model made by a quick fit of the plant).
    let model = dir.join("model.json");
    let o = run(&[
        "--quiet",
        "fit",
        plant_s,
        "--modes",
        "2",
        "--out",
        model.to_str().unwrap(),
    ]);
    if o.status.success() {
        let json = std::fs::read(&model).unwrap();
        for m in 0..40 {
            let data = mutate(&json, &mut rng, m);
            let path = dir.join(format!("model{m}.json"));
            std::fs::write(&path, &data).unwrap();
            no_panic(
                &[
                    "eval",
                    path.to_str().unwrap(),
                    "--at",
                    plant_s,
                    "--out",
                    out_s,
                ],
                &path,
                &mut runs,
            );
            let _ = std::fs::remove_file(&path);
        }
    } else {
        println!(
            "fit of the plant failed, model JSON not mutated: {}",
            stderr(&o)
        );
    }
    println!("{runs} runs of frfit, {errors} inputs refused with an error, no panic");
    assert!(
        errors > 50,
        "the mutations should break most files ({errors})"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
