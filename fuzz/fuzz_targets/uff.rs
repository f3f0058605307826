//! UFF reader (ASCII and binary 58b, other datasets skipped): any bytes give an FRF or
//! an error, never a panic, a hang or an allocation beyond 10x the input.
#![no_main]
mod alloc_limit;

#[global_allocator]
static A: alloc_limit::Counting = alloc_limit::Counting;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let limit = alloc_limit::BASE + 10 * data.len();
    alloc_limit::check("uff", limit, || {
        let _ = frf_data::io::parse_uff58_bytes(data, "fuzz.uff");
    });
});
