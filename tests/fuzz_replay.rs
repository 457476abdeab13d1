//! Replays every committed fuzz corpus file (`tests/fuzz/corpus/<target>/`)
//! through the same target bodies the cargo-fuzz project runs
//! (`marionette_tests::fuzz_targets`), on stable, in `cargo test`. A target
//! body panics on any violated invariant, so this fails on any regression of
//! a fixed crash and on any corpus input that no longer holds.
//!
//! Each corpus must be non-empty and must reach its target's accepting path
//! at least once (so the corpora exercise the decoders and the live loop, not
//! only the rejections).
//!
//! The seeds the corpora grew from are written by
//! `cargo test -p marionette-tests --test fuzz_replay -- --ignored write_seed_corpus`.

use marionette_tests::fuzz_targets::{self, Outcome, TARGETS};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn corpus(target: &str) -> PathBuf {
    repo().join("tests/fuzz/corpus").join(target)
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.is_file())
        .collect();
    out.sort();
    out
}

#[test]
fn every_corpus_file_replays_without_a_panic() {
    let mut summary = Vec::new();
    for target in TARGETS {
        let dir = corpus(target.name);
        let inputs = files(&dir);
        assert!(!inputs.is_empty(), "{}: empty corpus", dir.display());
        let mut accepted = 0;
        for path in &inputs {
            let bytes = std::fs::read(path).expect("corpus file");
            let result = std::panic::catch_unwind(|| (target.run)(&bytes));
            match result {
                Ok(Outcome::Accepted) => accepted += 1,
                Ok(Outcome::Rejected) => {}
                Err(_) => panic!("{}: {} panicked", target.name, path.display()),
            }
        }
        assert!(
            accepted > 0,
            "{}: no corpus input reaches the accepting path",
            target.name
        );
        summary.push(format!(
            "{}: {} inputs, {accepted} accepted",
            target.name,
            inputs.len()
        ));
    }
    eprintln!("{}", summary.join("\n"));
}

/// The seeds are valid inputs: every one is accepted by its target.
#[test]
fn the_seeds_are_accepted() {
    for (target, name, bytes) in fuzz_targets::seeds(&repo()) {
        let t = TARGETS
            .iter()
            .find(|t| t.name == target)
            .expect("seed for a known target");
        assert_eq!((t.run)(&bytes), Outcome::Accepted, "seed {target}/{name}");
    }
}

/// Writes the seeds into the corpus folders (run by hand, see the module doc).
#[test]
#[ignore = "writes tests/fuzz/corpus; run by hand to reseed"]
fn write_seed_corpus() {
    for (target, name, bytes) in fuzz_targets::seeds(&repo()) {
        let dir = corpus(target);
        std::fs::create_dir_all(&dir).expect("corpus folder");
        std::fs::write(dir.join(format!("seed-{name}")), bytes).expect("seed file");
    }
}
