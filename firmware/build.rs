//! Picks the memory map of the selected board and, for the Black Pill, links defmt.
use std::{env, fs, path::PathBuf};

fn main() {
    let blackpill = env::var_os("CARGO_FEATURE_BLACKPILL").is_some();
    let board = if blackpill { "blackpill" } else { "qemu-an386" };
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let src = PathBuf::from("boards").join(board).join("memory.x");
    fs::copy(&src, out.join("memory.x")).expect("board memory.x exists");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", src.display());
    println!("cargo:rerun-if-changed=build.rs");
    if blackpill {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
