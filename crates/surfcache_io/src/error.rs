//! The one error type of the crate, and [`Untrusted`]: how a message shows text it did not
//! write itself.

use std::fmt::{self, Write as _};
use std::path::{Path, PathBuf};

/// A file that could not be read, parsed or written, or an unknown scene name.
///
/// Its `Display` is one printable line naming the file and the cause: the path and the
/// cause go through [`Untrusted`], so no byte of a file (or of a path) reaches a terminal
/// raw.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file could not be opened or is not parseable as the expected format at all.
    #[error(
        "cannot read {format} '{}': {}",
        Untrusted::path(path),
        Untrusted::cause(cause)
    )]
    Read {
        /// "glTF" or "EXR".
        format: &'static str,
        /// The file.
        path: PathBuf,
        /// What went wrong.
        cause: String,
    },
    /// The glTF file parsed but its content is invalid or unsupported.
    #[error("glTF '{}': {}", Untrusted::path(path), Untrusted::cause(cause))]
    Gltf {
        /// The glTF file.
        path: PathBuf,
        /// What is wrong, naming the buffer, image, mesh, accessor or vertex.
        cause: String,
    },
    /// The EXR file parsed but its content is invalid or unsupported.
    #[error("EXR '{}': {}", Untrusted::path(path), Untrusted::cause(cause))]
    Exr {
        /// The EXR file.
        path: PathBuf,
        /// What is wrong, e.g. the pixel and channel holding a NaN.
        cause: String,
    },
    /// The EXR file has no R, G and B channels.
    #[error(
        "EXR '{}' has no R, G, B channels (found: {})",
        Untrusted::path(path),
        Untrusted::text(found)
    )]
    MissingChannels {
        /// The EXR file.
        path: PathBuf,
        /// The channels it does have (at most eight, each through [`Untrusted::bytes`]), comma
        /// separated.
        found: String,
    },
    /// A file could not be written.
    #[error(
        "cannot write '{}': {}",
        Untrusted::path(path),
        Untrusted::cause(cause)
    )]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        cause: String,
    },
    /// `load_scene` got a name that is neither a glTF file nor a built-in scene.
    #[error("unknown built-in scene '{}' (known: {known})", Untrusted::name(name))]
    UnknownScene {
        /// The name asked for.
        name: String,
        /// The built-in scene names, comma separated.
        known: String,
    },
}

impl IoError {
    pub(crate) fn gltf(path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Gltf {
            path: path.to_path_buf(),
            cause: cause.to_string(),
        }
    }

    pub(crate) fn exr(path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Exr {
            path: path.to_path_buf(),
            cause: cause.to_string(),
        }
    }

    pub(crate) fn read(format: &'static str, path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Read {
            format,
            path: path.to_path_buf(),
            cause: cause.to_string(),
        }
    }

    pub(crate) fn write(path: &Path, cause: impl std::fmt::Display) -> Self {
        IoError::Write {
            path: path.to_path_buf(),
            cause: cause.to_string(),
        }
    }
}

/// Text a message quotes but did not write: a name, URI or excerpt read from a file, a path,
/// a command-line argument, a third-party error message. Its `Display` shows it as one
/// printable line:
///
/// - `\n`, `\r` and `\t` as those escapes, every other character Rust's `{:?}` would escape
///   as not printable (controls such as ESC, C1 controls, bidirectional overrides, line and
///   paragraph separators, zero-width and other format characters, combining marks) as
///   `\u{…}`, and bytes that are not UTF-8 as `\xNN`;
/// - backslashes and quotes as they are, so that escaping twice changes nothing and a
///   message may escape again what it quotes from an escaped part (so that both the one who
///   quotes a name and the one who prints the message can make sure of it);
/// - cut with "…" after [`Untrusted::NAME_CHARS`] characters (names) or
///   [`Untrusted::CAUSE_CHARS`] (causes); paths and whole messages are not cut.
///
/// ```
/// use surfcache_io::Untrusted;
/// let name = "wall\n\u{1b}[2Jred";
/// assert_eq!(Untrusted::name(name).to_string(), r"wall\n\u{1b}[2Jred");
/// assert_eq!(Untrusted::bytes(b"R\xff\x9b").to_string(), r"R\xff\x9b");
/// let long = "x".repeat(500);
/// assert_eq!(Untrusted::name(&long).to_string().chars().count(), Untrusted::NAME_CHARS + 1);
/// ```
#[derive(Clone, Copy)]
pub struct Untrusted<'a> {
    bytes: &'a [u8],
    /// Most characters shown (an escape counts its length), then "…".
    max_chars: usize,
}

impl<'a> Untrusted<'a> {
    /// Most characters [`Untrusted::name`] shows.
    pub const NAME_CHARS: usize = 80;

    /// A name, URI or other short text from a file: escaped and cut.
    pub fn name(text: &'a str) -> Self {
        Self::bytes(text.as_bytes())
    }

    /// Bytes that should be text but need not be UTF-8 (an EXR channel or attribute name):
    /// escaped and cut like [`Untrusted::name`].
    pub fn bytes(bytes: &'a [u8]) -> Self {
        Self {
            bytes,
            max_chars: Self::NAME_CHARS,
        }
    }

    /// Most characters [`Untrusted::cause`] shows.
    pub const CAUSE_CHARS: usize = 500;

    /// A cause, perhaps a third-party error message quoting an excerpt of the file:
    /// escaped, cut after [`Untrusted::CAUSE_CHARS`].
    pub fn cause(text: &'a str) -> Self {
        Self {
            bytes: text.as_bytes(),
            max_chars: Self::CAUSE_CHARS,
        }
    }

    /// A whole message, built of parts already cut: escaped, never cut.
    pub fn text(text: &'a str) -> Self {
        Self {
            bytes: text.as_bytes(),
            max_chars: usize::MAX,
        }
    }

    /// A path: its bytes escaped (not UTF-8 ones as `\xNN` on Unix), never cut.
    pub fn path(path: &'a Path) -> Self {
        Self {
            bytes: path.as_os_str().as_encoded_bytes(),
            max_chars: usize::MAX,
        }
    }
}

impl fmt::Display for Untrusted<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut shown = 0usize;
        // Pushes one escape or character unless it would pass the limit.
        let mut put = |f: &mut fmt::Formatter<'_>, piece: &str| -> Result<bool, fmt::Error> {
            let n = piece.chars().count();
            if shown.saturating_add(n) > self.max_chars {
                f.write_char('…')?;
                return Ok(false);
            }
            shown += n;
            f.write_str(piece)?;
            Ok(true)
        };
        let mut buf = String::new();
        for chunk in self.bytes.utf8_chunks() {
            for c in chunk.valid().chars() {
                buf.clear();
                match c {
                    '\\' | '\'' | '"' => buf.push(c),
                    _ => write!(buf, "{}", c.escape_debug())?,
                }
                if !put(f, &buf)? {
                    return Ok(());
                }
            }
            for b in chunk.invalid() {
                buf.clear();
                write!(buf, "\\x{b:02x}")?;
                if !put(f, &buf)? {
                    return Ok(());
                }
            }
        }
        Ok(())
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

#[cfg(test)]
mod tests {
    use super::Untrusted;

    #[test]
    fn escapes_what_is_not_printable_once_and_cuts_between_escapes() {
        let raw = "a\u{1b}[2J\r\n\t\0\u{7f}\u{85}\u{9b}\u{202e}\u{2028}\u{feff}é 漢 '\"\\";
        let shown = Untrusted::text(raw).to_string();
        assert_eq!(
            shown,
            r#"a\u{1b}[2J\r\n\t\0\u{7f}\u{85}\u{9b}\u{202e}\u{2028}\u{feff}é 漢 '"\"#
        );
        // Escaping what is already escaped changes nothing.
        assert_eq!(Untrusted::text(&shown).to_string(), shown);
        // Bytes that are not UTF-8, a cut sequence among them.
        assert_eq!(
            Untrusted::bytes(b"R\xff\xe2\x80.G").to_string(),
            r"R\xff\xe2\x80.G"
        );
        // A cut never splits an escape: `\u{1b}` does not fit in the last 3 characters.
        let long = format!("{}\u{1b}", "x".repeat(Untrusted::NAME_CHARS - 3));
        let cut = Untrusted::name(&long).to_string();
        assert_eq!(cut, format!("{}…", "x".repeat(Untrusted::NAME_CHARS - 3)));
        let exact = "x".repeat(Untrusted::NAME_CHARS);
        assert_eq!(Untrusted::name(&exact).to_string(), exact);
        let path = std::path::Path::new("dir/a\nb.exr");
        assert_eq!(Untrusted::path(path).to_string(), r"dir/a\nb.exr");
    }
}
