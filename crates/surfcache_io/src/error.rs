//! The one error type of the crate.

use std::path::{Path, PathBuf};

/// A file that could not be read, parsed or written, or an unknown scene name.
///
/// Its `Display` is one line naming the file and the cause.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file could not be opened or is not parseable as the expected format at all.
    #[error("cannot read {format} '{}': {cause}", path.display())]
    Read {
        /// "glTF" or "EXR".
        format: &'static str,
        /// The file.
        path: PathBuf,
        /// What went wrong.
        cause: String,
    },
    /// The glTF file parsed but its content is invalid or unsupported.
    #[error("glTF '{}': {cause}", path.display())]
    Gltf {
        /// The glTF file.
        path: PathBuf,
        /// What is wrong, naming the buffer, image, mesh, accessor or vertex.
        cause: String,
    },
    /// The EXR file parsed but its content is invalid or unsupported.
    #[error("EXR '{}': {cause}", path.display())]
    Exr {
        /// The EXR file.
        path: PathBuf,
        /// What is wrong, e.g. the pixel and channel holding a NaN.
        cause: String,
    },
    /// The EXR file has no R, G and B channels.
    #[error("EXR '{}' has no R, G, B channels (found: {found})", path.display())]
    MissingChannels {
        /// The EXR file.
        path: PathBuf,
        /// The channels it does have, comma separated.
        found: String,
    },
    /// A file could not be written.
    #[error("cannot write '{}': {cause}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        cause: String,
    },
    /// `load_scene` got a name that is neither a glTF file nor a built-in scene.
    #[error("unknown built-in scene '{name}' (known: {known})")]
    UnknownScene {
        /// The name asked for.
        name: String,
        /// The built-in scene names, comma separated.
        known: String,
    },
}

/// Flattens a cause to one line.
pub(crate) fn one_line(cause: impl std::fmt::Display) -> String {
    let s = cause.to_string();
    if s.contains('\n') {
        s.split('\n')
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect::<Vec<_>>()
            .join("; ")
    } else {
        s
    }
}

impl IoError {
    pub(crate) fn gltf(path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Gltf {
            path: path.to_path_buf(),
            cause: one_line(cause),
        }
    }

    pub(crate) fn exr(path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Exr {
            path: path.to_path_buf(),
            cause: one_line(cause),
        }
    }

    pub(crate) fn read(format: &'static str, path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Read {
            format,
            path: path.to_path_buf(),
            cause: one_line(cause),
        }
    }

    pub(crate) fn write(path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Write {
            path: path.to_path_buf(),
            cause: one_line(cause),
        }
    }
}

/// Runs `f`, turning a panic inside a third-party decoder into an error message.
pub(crate) fn no_panic<T>(what: &str, f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        let msg = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown cause".into());
        format!("{what} failed on malformed data ({msg})")
    })
}
