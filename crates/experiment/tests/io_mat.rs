//! MATLAB `.mat` files: the own level-5 reader against an independent one (`matrw`) on
//! the reference files, FRF files (`G`, `freq_hz`) bit-exact, and a deterministic corpus
//! of damaged files that must give errors, never panics.

use experiment::matfile::MatFile;
use frf_data::io::mat5::{parse_mat5, MatValue};
use frf_data::io::{frf_mat_bytes, parse_frf_mat, read_frf_csv};
use frf_data::shared_data::require;
use frf_data::FrfDataset;

/// `matrw`'s numeric arrays as (name, dims, real, imag).
type Arr = (String, Vec<usize>, Vec<f64>, Option<Vec<f64>>);

fn matrw_arrays(bytes: &[u8]) -> Vec<Arr> {
    use matrw::MatlabType as T;
    fn to_f64(t: &T) -> Option<Vec<f64>> {
        Some(match t {
            T::U8(v) => v.iter().map(|&x| x as f64).collect(),
            T::I8(v) => v.iter().map(|&x| x as f64).collect(),
            T::U16(v) => v.iter().map(|&x| x as f64).collect(),
            T::I16(v) => v.iter().map(|&x| x as f64).collect(),
            T::U32(v) => v.iter().map(|&x| x as f64).collect(),
            T::I32(v) => v.iter().map(|&x| x as f64).collect(),
            T::U64(v) => v.iter().map(|&x| x as f64).collect(),
            T::I64(v) => v.iter().map(|&x| x as f64).collect(),
            T::F32(v) => v.iter().map(|&x| x as f64).collect(),
            T::F64(v) => v.clone(),
            _ => return None,
        })
    }
    let m = matrw::load_matfile_from_u8(bytes).expect("matrw reads the reference file");
    let mut out = Vec::new();
    for (name, var) in m.iter() {
        if let matrw::MatVariable::NumericArray(a) = var {
            if let (false, Some(re)) = (name.is_empty(), to_f64(&a.value)) {
                let mut dims = a.dim.clone();
                while dims.len() < 2 {
                    dims.push(1);
                }
                out.push((
                    name.clone(),
                    dims,
                    re,
                    a.value_cmp.as_ref().and_then(to_f64),
                ));
            }
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn reference_files_read_as_an_independent_reader_reads_them() {
    for name in [
        "real/fditools_motorbench_msA.mat",
        "real/daisy_flexible_structure.mat",
    ] {
        let Some(path) = require(
            "reference_files_read_as_an_independent_reader_reads_them",
            name,
        ) else {
            continue;
        };
        let bytes = std::fs::read(&path).unwrap();
        let want = matrw_arrays(&bytes);
        let mut got: Vec<Arr> = parse_mat5(&bytes, name)
            .unwrap()
            .into_iter()
            .filter(|v| !v.name.is_empty())
            .filter_map(|v| match v.value {
                MatValue::Numeric { dims, real, imag } => Some((v.name, dims, real, imag)),
                MatValue::Other(_) => None,
            })
            .collect();
        got.sort_by(|a, b| a.0.cmp(&b.0));
        assert!(!want.is_empty(), "{name}");
        assert_eq!(got, want, "{name}");
        let mf = MatFile::from_bytes(&bytes, name).unwrap();
        assert_eq!(mf.names().len(), want.len(), "{name}");
    }
    // The motor bench record: the names FORMATS.md lists, and the `tf` object skipped.
    if let Some(path) = require(
        "reference_files_read_as_an_independent_reader_reads_them",
        "real/fditools_motorbench_msA.mat",
    ) {
        let mf = MatFile::read(&path).unwrap();
        assert_eq!(mf.scalar("fs"), Some(2500.0));
        assert_eq!(mf.signal("iq_adx").unwrap().len(), 50_000);
        assert!(!mf.skipped.is_empty(), "{:?}", mf.skipped);
    }
}

#[test]
fn frf_mat_round_trip_is_bit_exact() {
    let Some(path) = require("frf_mat_round_trip_is_bit_exact", "wafer_nominal.csv") else {
        return;
    };
    let csv = read_frf_csv(&path).unwrap();
    let back = parse_frf_mat(&frf_mat_bytes(&csv), "wafer.mat").unwrap();
    assert_eq!((back.ny(), back.nu(), back.n_lines()), (4, 13, 4000));
    assert_eq!(back.values(), csv.values());
    assert_eq!(back.freq_hz_slice(), csv.freq_hz_slice());
    assert_eq!(back.variances(), csv.variances());
}

/// A small deterministic generator (xorshift64*).
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

/// Mutated copies of `bytes`: bit flips, byte runs, truncations, duplicated and deleted
/// chunks, length fields set to huge values.
fn mutants(bytes: &[u8], n: usize, seed: u64) -> Vec<Vec<u8>> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|q| {
            let mut b = bytes.to_vec();
            let len = b.len();
            match q % 6 {
                0 => {
                    for _ in 0..1 + rng.below(8) {
                        let i = rng.below(len);
                        b[i] ^= 1 << rng.below(8);
                    }
                }
                1 => b.truncate(rng.below(len)),
                2 => {
                    let i = rng.below(len);
                    let k = rng.below(64).min(len - i);
                    let chunk = b[i..i + k].to_vec();
                    let at = rng.below(len);
                    b.splice(at..at, chunk);
                }
                3 => {
                    let i = rng.below(len);
                    let k = rng.below(256).min(len - i);
                    b.drain(i..i + k);
                }
                4 => {
                    // A 4-byte field (tag type or size) set to something huge.
                    let i = (128 + 4 * rng.below((len - 128) / 4)).min(len - 4);
                    let v = [0xffff_fff0u32, 0x7fff_ffff, 0x0001_0000, 15, 14][rng.below(5)];
                    b[i..i + 4].copy_from_slice(&v.to_le_bytes());
                }
                _ => {
                    let i = rng.below(len);
                    let k = rng.below(32).min(len - i);
                    let x = rng.next() as u8;
                    b[i..i + k].iter_mut().for_each(|y| *y = x);
                }
            }
            b
        })
        .collect()
}

#[test]
fn damaged_mat_files_give_errors_not_panics() {
    let mut sources: Vec<(String, Vec<u8>)> = Vec::new();
    if let Some(p) = require(
        "damaged_mat_files_give_errors_not_panics",
        "real/fditools_motorbench_msA.mat",
    ) {
        sources.push(("motorbench".into(), std::fs::read(p).unwrap()));
    }
    // Always: a small FRF file made here.
    let f = frf_data::Frf::from_fn(vec![1.0, 2.0, 3.0], 2, 1, |k, i, _| {
        frf_data::C64::new(k as f64, i as f64)
    })
    .unwrap();
    sources.push(("frf".into(), frf_mat_bytes(&f)));
    let mut errors = 0;
    for (name, bytes) in &sources {
        for (q, m) in mutants(bytes, 300, 0x5eed ^ bytes.len() as u64)
            .iter()
            .enumerate()
        {
            let what = format!("{name} mutant {q}");
            let a = MatFile::from_bytes(m, &what);
            let b = parse_frf_mat(m, &what);
            if let Err(e) = &a {
                assert!(e.to_string().contains(&what), "{e}");
                errors += 1;
            }
            if let Err(e) = &b {
                assert!(e.to_string().contains(&what), "{e}");
            }
        }
    }
    println!("{errors} damaged files gave errors");
    assert!(errors > 0);
}
