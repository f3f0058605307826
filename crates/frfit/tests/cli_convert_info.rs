//! `frfit info` on the spreadsheet, UFF and MATLAB variants of one FRF (made here) reads
//! the same numbers as the plain CSV and says which variant it read; `frfit convert`
//! between the formats keeps every bit where the target format can hold it.

mod common;

use common::{run, stderr, stdout, temp_dir, write_plant};
use frf_data::io::read_frf;
use std::path::Path;

fn info_json(path: &Path) -> serde_json::Value {
    let o = run(&["info", "--json", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}: {}", path.display(), stderr(&o));
    serde_json::from_str(&stdout(&o)).unwrap()
}

#[track_caller]
fn convert(args: &[&str]) {
    let mut a = vec!["--quiet", "convert"];
    a.extend_from_slice(args);
    let o = run(&a);
    assert!(o.status.success(), "convert {args:?}: {}", stderr(&o));
}

#[test]
fn info_reads_every_variant_alike_and_names_it() {
    let dir = temp_dir("convert-info");
    let plant = write_plant(&dir, 0.0);
    let plain_text = std::fs::read_to_string(&plant).unwrap();
    let want = read_frf(&plant).unwrap();
    let plain = info_json(&plant);
    assert!(
        plain["format"].as_str().unwrap().contains("`,` separator"),
        "{plain}"
    );
    // A spreadsheet in a comma-decimal locale.
    let excel: String = plain_text
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                format!("{l}\r\n")
            } else if l.starts_with("freq_hz") {
                let h: Vec<String> = l.split(',').map(|x| format!("\"{x}\"")).collect();
                format!("{}\r\n", h.join(";"))
            } else {
                format!("{}\r\n", l.replace(',', ";").replace('.', ","))
            }
        })
        .collect();
    let excel_path = dir.join("excel.csv");
    std::fs::write(&excel_path, format!("\u{feff}{excel}")).unwrap();
    let p = |n: &str| dir.join(n);
    let s = |n: &str| dir.join(n).to_str().unwrap().to_string();
    convert(&[plant.to_str().unwrap(), &s("plant.mat")]);
    convert(&[plant.to_str().unwrap(), &s("plant.uff")]);
    convert(&[plant.to_str().unwrap(), &s("plant_le.uff"), "--uff-binary"]);
    convert(&[
        plant.to_str().unwrap(),
        &s("plant_be32.unv"),
        "--uff-binary",
        "--single",
        "--big-endian",
    ]);
    for (file, format_has, exact) in [
        (
            excel_path.clone(),
            "`;` separator, `,` decimal mark, CRLF",
            true,
        ),
        (p("plant.mat"), "MATLAB .mat", true),
        (p("plant.uff"), "ASCII", false),
        (p("plant_le.uff"), "binary (58b)", true),
        (p("plant_be32.unv"), "binary (58b), complex single", false),
    ] {
        let v = info_json(&file);
        let f = v["format"].as_str().unwrap();
        assert!(f.contains(format_has), "{}: format `{f}`", file.display());
        for key in ["ny", "nu", "n_lines"] {
            assert_eq!(v[key], plain[key], "{}: {key}", file.display());
        }
        let got = read_frf(&file).unwrap();
        assert_eq!(
            got.freq_hz_slice(),
            want.freq_hz_slice(),
            "{}",
            file.display()
        );
        if exact {
            assert_eq!(got.values(), want.values(), "{}", file.display());
        } else {
            // ASCII UFF: 13 significant digits; single precision: 24 bits.
            let tol = if f.contains("single") { 1e-7 } else { 1e-12 };
            for (a, b) in got.values().iter().zip(want.values()) {
                assert!(
                    (a - b).norm() <= tol * b.norm().max(1e-300),
                    "{}",
                    file.display()
                );
            }
        }
    }
    // Back to CSV: bit for bit from .mat and binary UFF, variances kept by .mat.
    convert(&[&s("plant.mat"), &s("back_mat.csv")]);
    let back = read_frf(p("back_mat.csv")).unwrap();
    assert_eq!(back.values(), want.values());
    assert_eq!(back.variances(), want.variances());
    convert(&[&s("plant_le.uff"), &s("back_uff.csv")]);
    assert_eq!(read_frf(p("back_uff.csv")).unwrap().values(), want.values());
    // Unknown output extension and a misplaced option are argument errors.
    let o = run(&["convert", plant.to_str().unwrap(), &s("x.txt")]);
    assert!(
        !o.status.success() && stderr(&o).contains("x.txt"),
        "{}",
        stderr(&o)
    );
    let o = run(&[
        "convert",
        plant.to_str().unwrap(),
        &s("x.csv"),
        "--uff-binary",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("--uff-binary"),
        "{}",
        stderr(&o)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn info_refuses_a_mat_file_without_an_frf_naming_what_it_holds() {
    let dir = temp_dir("mat-no-frf");
    let path = dir.join("t.mat");
    let bytes = frf_data::io::mat5::mat5_bytes(&[frf_data::io::mat5::MatWrite {
        name: "y",
        dims: &[4, 1],
        real: &[1.0, 2.0, 3.0, 4.0],
        imag: None,
    }]);
    std::fs::write(&path, bytes).unwrap();
    let o = run(&["info", path.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("`G`") && e.contains("`y` (4x1 real)"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
