//! Fuzz target `wire`: see `marionette_tests::fuzz_targets::wire`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = marionette_tests::fuzz_targets::wire(data);
});
