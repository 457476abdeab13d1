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

/// A cargo command for the nested firmware build in `dir`, without the outer
/// build's flags and wrappers ([`OUTER_ENV`]). With rustup, the firmware
/// always builds with the toolchain `rust-toolchain.toml` pins (the one with
/// the firmware's target, on which the firmware is checked panic-never),
/// even when another runs the outer build (`cargo +nightly fuzz`): rustup's
/// `cargo` proxy (in `$CARGO_HOME/bin`), without the outer
/// `RUSTUP_TOOLCHAIN`, reads that file. Without rustup, the outer cargo.
fn firmware_cargo(dir: &std::path::Path) -> std::process::Command {
    let home = std::env::var_os("CARGO_HOME")
        .map(std::path::PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| std::path::Path::new(&h).join(".cargo")));
    let proxy = home
        .filter(|_| std::env::var_os("RUSTUP_TOOLCHAIN").is_some())
        .map(|h| h.join("bin").join("cargo"))
        .filter(|p| p.is_file());
    let cargo = match &proxy {
        Some(p) => p.clone().into_os_string(),
        None => std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()),
    };
    let mut cmd = std::process::Command::new(cargo);
    cmd.current_dir(dir);
    for var in OUTER_ENV {
        cmd.env_remove(var);
    }
    if proxy.is_some() {
        cmd.env_remove("RUSTUP_TOOLCHAIN")
            .env_remove("RUSTUP_TOOLCHAIN_SOURCE");
    }
    cmd
}
