//! MATLAB level-5 reader (as time records and as an FRF file): any bytes give variables
//! or an error, never a panic or a hang. Compressed variables inflate by up to 1032:1
//! (zlib's largest ratio), so the allocation bound is 10x the input times that ratio.
#![no_main]
mod alloc_limit;

#[global_allocator]
static A: alloc_limit::Counting = alloc_limit::Counting;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let limit = alloc_limit::BASE + 10 * 1032 * data.len();
    alloc_limit::check("mat", limit, || {
        let _ = experiment::matfile::MatFile::from_bytes(data, "fuzz.mat");
        let _ = frf_data::io::parse_frf_mat(data, "fuzz.mat");
    });
});
