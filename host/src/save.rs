//! Writing output files safely. Every file a command writes goes through
//! here, so that all of them behave alike:
//!
//! - **never half-written**: the bytes go to a temporary file in the target's
//!   folder, which is renamed over the target only when complete (a failure
//!   leaves the old file, or none);
//! - **never over an input**: a target that is one of the command's input
//!   files (the same file, by device and inode, whatever the path says) is
//!   refused before anything is written;
//! - **folders made**: missing parent folders are created.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Why a file could not be saved.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    /// The target is one of the command's inputs.
    #[error("{path}: is an input of this command ({what}); choose another output file")]
    Input {
        /// The target.
        path: PathBuf,
        /// Which input.
        what: String,
    },
    /// The target is a folder.
    #[error("{0}: is a folder; give a file name")]
    Folder(PathBuf),
    /// Writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What went wrong.
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SaveError + '_ {
    move |source| SaveError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Whether two paths name the same existing file.
#[must_use]
pub fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
        _ => false,
    }
}

/// Refuses `path` if it is one of `inputs` (`(what, path)` pairs) or a
/// folder.
pub fn check(path: &Path, inputs: &[(&str, &Path)]) -> Result<(), SaveError> {
    if path.is_dir() {
        return Err(SaveError::Folder(path.to_path_buf()));
    }
    match inputs.iter().find(|(_, input)| same_file(path, input)) {
        Some((what, _)) => Err(SaveError::Input {
            path: path.to_path_buf(),
            what: (*what).to_owned(),
        }),
        None => Ok(()),
    }
}

/// Creates the folder `path` will be written in.
pub fn make_parent(path: &Path) -> Result<PathBuf, SaveError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(io(&dir))?;
    Ok(dir)
}

/// A temporary file beside `path` with the same extension (drawing
/// back-ends pick the format by it); deleted unless [`commit`]ted.
pub fn temp_beside(path: &Path) -> Result<tempfile::NamedTempFile, SaveError> {
    let dir = make_parent(path)?;
    let ext = path
        .extension()
        .map_or_else(String::new, |e| format!(".{}", e.to_string_lossy()));
    tempfile::Builder::new()
        .prefix(".marionette-")
        .suffix(&ext)
        .tempfile_in(&dir)
        .map_err(io(&dir))
}

/// Moves a finished temporary file over `path`.
pub fn commit(temp: tempfile::NamedTempFile, path: &Path) -> Result<(), SaveError> {
    temp.persist(path).map_err(|e| SaveError::Io {
        path: path.to_path_buf(),
        source: e.error,
    })?;
    Ok(())
}

/// Writes `bytes` to `path` (see the module doc).
pub fn save(path: &Path, bytes: &[u8], inputs: &[(&str, &Path)]) -> Result<(), SaveError> {
    save_with(path, inputs, |w| w.write_all(bytes))
}

/// Writes to `path` through `write` (see the module doc).
pub fn save_with(
    path: &Path,
    inputs: &[(&str, &Path)],
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), SaveError> {
    check(path, inputs)?;
    let mut temp = temp_beside(path)?;
    {
        let mut out = std::io::BufWriter::new(temp.as_file_mut());
        write(&mut out).map_err(io(path))?;
        out.flush().map_err(io(path))?;
    }
    commit(temp, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saves_whole_files_into_new_folders() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a/b/c.txt");
        save(&path, b"one", &[]).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        // A failing writer leaves the old file and no temporary one.
        let err = save_with(&path, &[], |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        let names: Vec<_> = std::fs::read_dir(dir.path().join("a/b"))
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("c.txt")]);
    }

    #[test]
    fn never_over_an_input_whatever_the_path_says() {
        let dir = tempfile::tempdir().unwrap();
        let spec = dir.path().join("spec.toml");
        std::fs::write(&spec, "x").unwrap();
        let other_name = dir.path().join(".").join("spec.toml");
        let err = save(&other_name, b"blob", &[("the build spec", &spec)]).unwrap_err();
        assert!(err.to_string().contains("the build spec"), "{err}");
        assert_eq!(std::fs::read(&spec).unwrap(), b"x");
        let err = save(dir.path(), b"blob", &[]).unwrap_err();
        assert!(err.to_string().contains("is a folder"), "{err}");
    }
}
