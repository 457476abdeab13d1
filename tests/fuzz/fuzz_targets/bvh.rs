//! Fuzz target `bvh`: see `marionette_tests::fuzz_targets::bvh_text`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = marionette_tests::fuzz_targets::bvh_text(data);
});
