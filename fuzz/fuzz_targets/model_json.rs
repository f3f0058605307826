//! Model JSON (`additive_riv::ModelFile`, parsed and turned into a model as `frfit eval`
//! does): any bytes give a model or an error, never a panic, a hang or an allocation
//! beyond 10x the input.
#![no_main]
mod alloc_limit;

#[global_allocator]
static A: alloc_limit::Counting = alloc_limit::Counting;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let limit = alloc_limit::BASE + 10 * text.len();
    alloc_limit::check("model_json", limit, || {
        if let Ok(f) = serde_json::from_str::<additive_riv::ModelFile>(&text) {
            let _ = f.to_model();
        }
    });
});
