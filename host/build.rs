//! Builds what `marionette` carries inside itself, so that it runs from any
//! folder without cargo or the source tree:
//!
//! - the emulated board's firmware (`firmware/`, its own workspace, built for
//!   `thumbv7em-none-eabihf` with a nested `cargo build --release --bins` into
//!   `firmware/target`, the folder `tests/run` builds it in too): every
//!   `[[bin]]` that requires the `qemu` feature;
//! - the bundled rigs (`rigs/*.toml`) and the demo's data (its build spec, the
//!   HDM05 mocap that spec reads, and the held-out recording).
//!
//! It writes `bundle.rs` into `OUT_DIR`: `include_bytes!` of each file, which
//! `host/src/bundle.rs` includes.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::{env, fs};

include!("firmware_build.rs");

/// The demo's data, relative to the repository root.
const DEMO_DATA: [&str; 11] = [
    "data/builds/reach_humanoid16.toml",
    "data/builds/walk_humanoid16.toml",
    "data/cmu_16_walk_run/16_21.bvh",
    "data/cmu_16_walk_run/16_45.bvh",
    "data/hdm05_bk/HDM_bk.asf",
    "data/hdm05_bk/HDM_bk_grabHighR_005_120.amc",
    "data/hdm05_bk/HDM_bk_grabHighR_006_120.amc",
    "data/hdm05_bk/HDM_bk_grabHighR_008_120.amc",
    "data/hdm05_bk/HDM_bk_depositFloorR_009_120.amc",
    "data/hdm05_bk/HDM_bk_depositFloorR_011_120.amc",
    "data/recordings/reach_hdm05_007.csv",
];

fn main() {
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let root = manifest.join("..");
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let firmware = root.join("firmware");
    for watched in [
        "firmware/src",
        "firmware/boards",
        "firmware/build.rs",
        "firmware/Cargo.toml",
        "firmware/Cargo.lock",
        "firmware/.cargo/config.toml",
        "shared/src",
        "shared/Cargo.toml",
        "rigs",
    ] {
        println!("cargo:rerun-if-changed={}", root.join(watched).display());
    }
    println!("cargo:rerun-if-changed=build.rs");

    let bins = emulated_bins(&firmware.join("Cargo.toml"));
    let elfs = build_firmware(&firmware, &bins);
    let mut rigs: Vec<String> = fs::read_dir(root.join("rigs"))
        .expect("rigs/ exists")
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(".toml"))
        .map(|name| format!("rigs/{name}"))
        .collect();
    rigs.sort();

    let mut code = String::from("/// The embedded firmware ELFs: `(binary name, bytes)`.\n");
    code.push_str("pub const FIRMWARE: &[(&str, &[u8])] = &[\n");
    for (bin, elf) in bins.iter().zip(&elfs) {
        writeln!(code, "    ({bin:?}, include_bytes!({:?})),", elf.display()).unwrap();
    }
    code.push_str("];\n/// The bundled files: `(path relative to the repository, bytes)`.\n");
    code.push_str("pub const FILES: &[(&str, &[u8])] = &[\n");
    let bundled: Vec<(&str, PathBuf)> = rigs
        .iter()
        .map(String::as_str)
        .chain(DEMO_DATA)
        .map(|rel| {
            (
                rel,
                root.join(rel).canonicalize().expect("bundled file exists"),
            )
        })
        .collect();
    for (rel, path) in &bundled {
        writeln!(code, "    ({rel:?}, include_bytes!({:?})),", path.display()).unwrap();
    }
    code.push_str("];\n");
    let mut hash = Fnv::default();
    let firmware_files = bins.iter().map(String::as_str).zip(&elfs);
    for (name, path) in firmware_files.chain(bundled.iter().map(|(n, p)| (*n, p))) {
        hash.write(name.as_bytes());
        hash.write(&fs::read(path).expect("bundled file reads"));
    }
    writeln!(
        code,
        "/// FNV-1a hash of every embedded name and byte, hex."
    )
    .unwrap();
    writeln!(code, "pub const HASH: &str = \"{:016x}\";", hash.0).unwrap();
    fs::write(out.join("bundle.rs"), code).expect("OUT_DIR is writable");
}

/// The firmware's `[[bin]]`s for the emulated board: those whose
/// `required-features` name `qemu` (read line by line from its Cargo.toml).
fn emulated_bins(manifest: &Path) -> Vec<String> {
    let text = fs::read_to_string(manifest).expect("firmware/Cargo.toml reads");
    let mut bins = Vec::new();
    for section in text.split("[[bin]]").skip(1) {
        let section = section.split("\n[").next().unwrap_or(section);
        let value = |key: &str| {
            section
                .lines()
                .find_map(|l| l.trim().strip_prefix(key)?.trim().strip_prefix('='))
                .map(str::trim)
        };
        let name = value("name").map(|v| v.trim_matches('"').to_string());
        let features = value("required-features").unwrap_or("");
        if let Some(name) = name.filter(|_| features.contains("\"qemu\"")) {
            bins.push(name);
        }
    }
    assert!(
        !bins.is_empty(),
        "firmware/Cargo.toml names no emulated-board [[bin]]"
    );
    bins
}

/// Builds the firmware binaries (release, panic-never) and copies the ELFs of
/// `bins` into `OUT_DIR`, returning the copies' paths in that order.
fn build_firmware(firmware: &Path, bins: &[String]) -> Vec<PathBuf> {
    let target_dir = firmware.join("target");
    let mut cmd = firmware_cargo(firmware);
    cmd.args(["build", "--quiet", "--release", "--bins", "--target-dir"])
        .arg(&target_dir);
    let status = cmd.status().expect("cargo runs");
    assert!(
        status.success(),
        "building the firmware in {} failed ({status}); it needs the target {TARGET} \
         (`rustup target add {TARGET}`, or `.ci/setup`)",
        firmware.display()
    );
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    bins.iter()
        .map(|bin| {
            let built = target_dir.join(TARGET).join("release").join(bin);
            let copy = out.join(format!("{bin}.elf"));
            fs::copy(&built, &copy).expect("the firmware build made the ELF");
            copy
        })
        .collect()
}

/// FNV-1a, 64 bits: names the run-time bundle folder after its content.
struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
}
