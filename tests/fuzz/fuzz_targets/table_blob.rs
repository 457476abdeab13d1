//! Fuzz target `table_blob`: see `marionette_tests::fuzz_targets::table_blob`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = marionette_tests::fuzz_targets::table_blob(data);
});
