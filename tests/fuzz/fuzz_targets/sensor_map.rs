//! Fuzz target `sensor_map`: see `marionette_tests::fuzz_targets::sensor_map`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = marionette_tests::fuzz_targets::sensor_map(data);
});
