//! Fuzz target `amc`: see `marionette_tests::fuzz_targets::amc_text`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = marionette_tests::fuzz_targets::amc_text(data);
});
