//! Periodic spectra CSV reader (input of the nonparametric estimator): any bytes give
//! spectra or an error, never a panic, a hang or an allocation beyond 10x the input.
#![no_main]
mod alloc_limit;

#[global_allocator]
static A: alloc_limit::Counting = alloc_limit::Counting;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let limit = alloc_limit::BASE + 10 * text.len();
    alloc_limit::check("spectra", limit, || {
        let _ = experiment::nonparametric::spectra_csv::parse_spectra_csv(&text, "fuzz.csv");
    });
});
