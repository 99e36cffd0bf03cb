//! Writing a file under a temporary name and renaming it into place.

use crate::IoError;
use std::io::Write;
use std::path::{Path, PathBuf};

/// A sibling temporary name for `path` (same directory, so the rename is atomic).
pub(crate) fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// Produces the file with `write` at a temporary name, then renames it to `path`; on any
/// error the temporary file is removed and `path` is left untouched.
pub(crate) fn replace_with(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), IoError> {
    let tmp = temp_sibling(path);
    let result = write(&tmp).and_then(|()| std::fs::rename(&tmp, path).map_err(|e| e.to_string()));
    if let Err(cause) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(IoError::write(path, cause));
    }
    Ok(())
}

/// Writes `bytes` to `path` atomically: to a temporary sibling file first (flushed to disk),
/// then renamed into place, so a reader never sees a half-written file under `path` and a
/// failure leaves `path` as it was.
pub fn write_file_atomically(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    replace_with(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        f.write_all(bytes).map_err(|e| e.to_string())?;
        f.sync_all().map_err(|e| e.to_string())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_whole_file_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("surfcache_replace_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("out.csv");
        write_file_atomically(&path, b"first, longer content\n").unwrap();
        write_file_atomically(&path, b"second\n").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second\n");
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["out.csv"]);

        // A missing directory is an error naming the file, and creates nothing.
        let missing = dir.join("no_such_dir").join("out.csv");
        let e = write_file_atomically(&missing, b"x")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("cannot write '") && e.contains("out.csv"),
            "{e}"
        );
        assert!(!e.contains('\n'), "{e}");
        assert!(!dir.join("no_such_dir").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
