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

/// Writes `bytes` to `path` through a temporary sibling file.
pub(crate) fn replace_bytes(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    replace_with(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        f.write_all(bytes).map_err(|e| e.to_string())?;
        f.sync_all().map_err(|e| e.to_string())
    })
}
