//! Reading and writing the FRF CSV: the 11 MB reference file `wafer_nominal.csv`
//! (4000 lines x 157 columns) from disk and from memory, and writing it back to text;
//! reading the same data from the UFF 58 file `uff/wafer_nominal.uff` (52 records).
//! Skips (with a message) when the shared data are not there.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use frf_data::io::{frf_csv_string, parse_frf_csv, read_frf_csv, read_uff58};
use frf_data::shared_data::{shared_file, skip_message};
use std::hint::black_box;

fn csv_read(c: &mut Criterion) {
    let Some(path) = shared_file("wafer_nominal.csv") else {
        println!("{}", skip_message("bench csv_read", "wafer_nominal.csv"));
        return;
    };
    let text = std::fs::read_to_string(&path).expect("the reference CSV is readable");
    let mut g = c.benchmark_group("frf_csv");
    g.sample_size(20);
    g.throughput(Throughput::Bytes(text.len() as u64));
    g.bench_function("read_file wafer_nominal.csv", |b| {
        b.iter(|| read_frf_csv(black_box(&path)).expect("reads"))
    });
    g.bench_function("parse_text wafer_nominal.csv", |b| {
        b.iter(|| parse_frf_csv(black_box(&text), "wafer_nominal.csv").expect("parses"))
    });
    let frf = parse_frf_csv(&text, "wafer_nominal.csv").expect("parses");
    g.bench_function("write_text wafer_nominal", |b| {
        b.iter(|| frf_csv_string(black_box(&frf), &frf.comments))
    });
    g.finish();

    let Some(uff) = shared_file("uff/wafer_nominal.uff") else {
        println!(
            "{}",
            skip_message("bench uff_read", "uff/wafer_nominal.uff")
        );
        return;
    };
    let mut g = c.benchmark_group("uff58");
    g.sample_size(10);
    g.bench_function("read_file wafer_nominal.uff", |b| {
        b.iter(|| read_uff58(black_box(&uff)).expect("reads"))
    });
    g.finish();
}

criterion_group!(benches, csv_read);
criterion_main!(benches);
