//! Fuzz target `rig_toml`: see `marionette_tests::fuzz_targets::rig_toml`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = marionette_tests::fuzz_targets::rig_toml(data);
});
