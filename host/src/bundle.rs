//! What the `marionette` binary carries inside itself, so that it works from
//! any folder, without cargo or the source tree (built by `host/build.rs`):
//!
//! - the emulated board's firmware ELFs (every `[[bin]]` of `firmware/` that
//!   requires the `qemu` feature: `perform`, `bench`, `echo`), built from
//!   `firmware/` at the same time as the host;
//! - the bundled rigs (`rigs/*.toml`) and the demo's data (its build spec,
//!   the HDM05 mocap the spec reads and the held-out recording).
//!
//! QEMU and the file readers want paths, so [`firmware()`] and [`file()`] write
//! the embedded bytes once into a folder under the system's temporary folder
//! named for their content (`marionette-<hash>/`, the repository's layout
//! inside) and return the path there. A file already there with the same
//! bytes is reused; writes go through a temporary file and a rename.
//!
//! Each build has its own folder, so a machine that runs many builds (a
//! developer's) would collect one per build, 11 MB each, in a temporary
//! folder that is often in memory. So each run stamps its folder
//! (`.last-used`) and removes the folders of other builds unused for a day
//! ([`STALE`]): named `marionette-` and 16 hex digits, real folders (not
//! links) owned by this user, their stamp (or, from builds before the
//! stamp, the folder itself) older than that. A board already running from
//! a removed folder keeps its open files; a later run of that build writes
//! its folder again.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, SystemTime};

/// Other builds' bundle folders unused for this long are removed.
pub const STALE: Duration = Duration::from_secs(24 * 3600);

/// The file whose modification time says when a bundle folder was last used.
const STAMP: &str = ".last-used";

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/bundle.rs"));
}

/// The ELF bytes of the embedded firmware binary `bin`.
#[must_use]
pub fn firmware_bytes(bin: &str) -> Option<&'static [u8]> {
    lookup(embedded::FIRMWARE, bin)
}

/// The bytes of the bundled file at `rel` (relative to the repository, e.g.
/// `rigs/humanoid16.toml`).
#[must_use]
pub fn file_bytes(rel: &str) -> Option<&'static [u8]> {
    lookup(embedded::FILES, rel)
}

/// A path holding the embedded firmware binary `bin`
/// (`<bundle>/firmware/<bin>.elf`), written on first use.
pub fn firmware(bin: &str) -> std::io::Result<PathBuf> {
    let bytes = firmware_bytes(bin).ok_or_else(|| not_bundled(bin))?;
    materialize(&Path::new("firmware").join(format!("{bin}.elf")), bytes)
}

/// A path holding the bundled file `rel` (`<bundle>/<rel>`); `None` if `rel`
/// is not bundled. The first call writes out every bundled file, so that
/// paths relative to one (a spec's mocap and rig) find the others.
pub fn file(rel: &Path) -> Option<std::io::Result<PathBuf>> {
    file_bytes(rel.to_str()?)?;
    static WRITTEN: OnceLock<Result<(), String>> = OnceLock::new();
    let written = WRITTEN.get_or_init(|| {
        embedded::FILES
            .iter()
            .try_for_each(|(name, bytes)| materialize(Path::new(name), bytes).map(drop))
            .map_err(|e| e.to_string())
    });
    Some(match written {
        Ok(()) => Ok(folder().join(rel)),
        Err(why) => Err(std::io::Error::other(why.clone())),
    })
}

fn lookup(list: &[(&str, &'static [u8])], name: &str) -> Option<&'static [u8]> {
    list.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
}

fn not_bundled(name: &str) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::NotFound,
        format!("`{name}` is not built into this marionette binary"),
    )
}

/// The bundle's folder: `marionette-<hash of every embedded byte>` in the
/// system's temporary folder, shared by every run of this build. If that
/// name is taken by another user (or is not a plain folder), a fresh private
/// folder `marionette-XXXXXX` is used instead.
#[must_use]
pub fn folder() -> &'static Path {
    static FOLDER: OnceLock<PathBuf> = OnceLock::new();
    FOLDER.get_or_init(|| {
        let tmp = std::env::temp_dir();
        let shared = tmp.join(format!("marionette-{}", embedded::HASH));
        if ours(&shared) {
            // Best effort: a folder that cannot be stamped or pruned still works.
            let now = SystemTime::now();
            let _ = std::fs::File::create(shared.join(STAMP)).and_then(|f| f.set_modified(now));
            prune(&tmp, &shared, now);
            return shared;
        }
        tempfile::Builder::new()
            .prefix("marionette-")
            .tempdir()
            .map_or(shared, tempfile::TempDir::keep)
    })
}

/// Whether `dir` is (now) a real folder owned by this process's user.
fn ours(dir: &Path) -> bool {
    use std::os::unix::fs::MetadataExt as _;
    let _ = std::fs::create_dir_all(dir);
    let probe = tempfile::NamedTempFile::new();
    match (std::fs::symlink_metadata(dir), probe) {
        (Ok(meta), Ok(probe)) => {
            meta.is_dir()
                && probe
                    .as_file()
                    .metadata()
                    .is_ok_and(|p| p.uid() == meta.uid())
        }
        _ => false,
    }
}

/// Removes the bundle folders in `tmp` other than `keep` that were last
/// used more than [`STALE`] before `now` (see the module doc); owned by the
/// owner of `keep`. Errors are ignored: another run may prune at the same
/// time.
fn prune(tmp: &Path, keep: &Path, now: SystemTime) {
    use std::os::unix::fs::MetadataExt as _;
    let (Ok(entries), Ok(mine)) = (std::fs::read_dir(tmp), std::fs::symlink_metadata(keep)) else {
        return;
    };
    let stale = |p: &Path| {
        std::fs::symlink_metadata(p)
            .and_then(|m| m.modified())
            .is_ok_and(|t| now.duration_since(t).is_ok_and(|age| age > STALE))
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if !bundle_name(&entry.file_name().to_string_lossy()) || path == keep {
            continue;
        }
        let ours =
            std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_dir() && m.uid() == mine.uid());
        let stamp = path.join(STAMP);
        let last_used = if stamp.exists() { &stamp } else { &path };
        if ours && stale(last_used) {
            let _ = std::fs::remove_dir_all(&path);
        }
    }
}

/// Whether `name` is a bundle folder's: `marionette-` and 16 hex digits.
fn bundle_name(name: &str) -> bool {
    name.strip_prefix("marionette-")
        .is_some_and(|h| h.len() == 16 && h.bytes().all(|b| b.is_ascii_hexdigit()))
}

/// Writes `bytes` to `<folder>/rel` unless that file already holds them.
fn materialize(rel: &Path, bytes: &[u8]) -> std::io::Result<PathBuf> {
    let path = folder().join(rel);
    if std::fs::read(&path).is_ok_and(|old| old == bytes) {
        return Ok(path);
    }
    let parent = path.parent().unwrap_or(folder());
    std::fs::create_dir_all(parent)?;
    let mut tmp = tempfile::NamedTempFile::new_in(parent)?;
    std::io::Write::write_all(&mut tmp, bytes)?;
    tmp.persist(&path).map_err(|e| e.error)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn firmware_and_files_are_the_ones_the_commands_need() {
        let bins: Vec<_> = embedded::FIRMWARE.iter().map(|(n, _)| *n).collect();
        for needed in ["perform", "bench", "echo"] {
            assert!(bins.contains(&needed), "{needed} in {bins:?}");
        }
        assert!(!bins.contains(&"blackpill"), "{bins:?}");
        for bin in bins {
            // An Arm ELF: magic, 32-bit, little-endian, machine 40 (EM_ARM).
            let elf = firmware_bytes(bin).unwrap();
            assert_eq!(&elf[..6], b"\x7fELF\x01\x01", "{bin}");
            assert_eq!(u16::from_le_bytes([elf[18], elf[19]]), 40, "{bin}");
        }
        let files: Vec<_> = embedded::FILES.iter().map(|(n, _)| *n).collect();
        for needed in [
            "rigs/humanoid16.toml",
            "rigs/cmu31.toml",
            "data/builds/reach_humanoid16.toml",
            "data/recordings/reach_hdm05_007.csv",
        ] {
            assert!(files.contains(&needed), "{needed} is bundled");
        }
    }

    /// Sets the modification time of `path` (a file or a folder).
    fn age(path: &Path, when: SystemTime) {
        std::fs::File::open(path)
            .unwrap()
            .set_modified(when)
            .unwrap();
    }

    #[test]
    fn other_builds_folders_unused_for_a_day_are_removed_and_nothing_else() {
        let tmp = tempfile::tempdir().unwrap();
        let now = SystemTime::now();
        let day_and_more = now - STALE - Duration::from_secs(60);
        let hour_ago = now - Duration::from_secs(3600);
        let dir = |name: &str| {
            let p = tmp.path().join(name);
            std::fs::create_dir_all(p.join("firmware")).unwrap();
            p
        };
        let keep = dir("marionette-0123456789abcdef");
        age(&keep, day_and_more);
        // Stamped long ago, and stamped within the day.
        let old = dir("marionette-00000000000000aa");
        std::fs::File::create(old.join(STAMP)).unwrap();
        age(&old.join(STAMP), day_and_more);
        let recent = dir("marionette-00000000000000bb");
        std::fs::File::create(recent.join(STAMP)).unwrap();
        age(&recent.join(STAMP), hour_ago);
        age(&recent, day_and_more);
        // From a build before the stamp: the folder's own time.
        let unstamped = dir("marionette-00000000000000cc");
        age(&unstamped, day_and_more);
        let unstamped_recent = dir("marionette-00000000000000dd");
        age(&unstamped_recent, hour_ago);
        // Not bundle folders: other names, a file, a link to an old bundle.
        let others = [
            dir("marionette-qemuAbC123"),
            dir("marionette-00000000000000e"),
            dir("marionette-00000000000000fg"),
            dir("something-0000000000000000"),
        ];
        for p in &others {
            age(p, day_and_more);
        }
        let file = tmp.path().join("marionette-1111111111111111");
        std::fs::write(&file, b"x").unwrap();
        age(&file, day_and_more);
        let link = tmp.path().join("marionette-2222222222222222");
        std::os::unix::fs::symlink(&old, &link).unwrap();
        prune(tmp.path(), &keep, now);
        assert!(!old.exists() && !unstamped.exists());
        assert!(keep.exists() && recent.exists() && unstamped_recent.exists());
        assert!(others.iter().all(|p| p.exists()));
        assert!(file.exists() && std::fs::symlink_metadata(&link).is_ok());
    }

    #[test]
    fn bundled_files_are_the_repository_files_and_land_on_disk_unchanged() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        for (rel, _) in embedded::FILES {
            let on_disk = std::fs::read(root.join(rel)).unwrap();
            assert_eq!(file_bytes(rel).unwrap(), on_disk.as_slice(), "{rel}");
            let written = file(Path::new(rel)).unwrap().unwrap();
            assert_eq!(std::fs::read(&written).unwrap(), on_disk, "{rel}");
            assert!(written.starts_with(folder()));
        }
        assert!(file(Path::new("rigs/none.toml")).is_none());
    }
}
