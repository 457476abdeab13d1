// How a nested cargo builds the firmware: included (`include!`) by
// `host/build.rs` and by `tests/examples/fit_cost.rs`, which both run
// `cargo build` in `firmware/` from inside another cargo.

/// The firmware's target triple (as in `firmware/.cargo/config.toml`).
const TARGET: &str = "thumbv7em-none-eabihf";

/// Environment a nested firmware build inherits from the outer cargo that
/// must not reach the firmware's cargo: flags, target and wrappers for the
/// host build.
const OUTER_ENV: [&str; 11] = [
    "RUSTFLAGS",
    "CARGO_ENCODED_RUSTFLAGS",
    "CARGO_BUILD_RUSTFLAGS",
    "CARGO_BUILD_TARGET",
    "CARGO_TARGET_DIR",
    "CARGO_BUILD_TARGET_DIR",
    "RUSTC",
    "RUSTC_WRAPPER",
    "RUSTC_WORKSPACE_WRAPPER",
    "CLIPPY_ARGS",
    "RUSTDOC",
];
