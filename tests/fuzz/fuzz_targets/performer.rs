//! Fuzz target `performer`: see `marionette_tests::fuzz_targets::performer`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = marionette_tests::fuzz_targets::performer(data);
});
