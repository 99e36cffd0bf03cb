//! Resolving the URIs of glTF buffers and images to files.

use crate::error::Untrusted;
use std::path::{Path, PathBuf};

/// Where a glTF URI points.
pub(crate) enum UriTarget {
    /// A `data:` URI, decoded by the gltf crate.
    Data,
    /// A file: the decoded path joined to the glTF file's directory.
    File(PathBuf),
}

/// Resolves a glTF URI (RFC 3986 relative reference or `file:`) against `base`.
pub(crate) fn resolve(uri: &str, base: &Path) -> Result<UriTarget, String> {
    if uri.starts_with("data:") {
        return Ok(UriTarget::Data);
    }
    if let Some(rest) = uri
        .strip_prefix("file://")
        .or_else(|| uri.strip_prefix("file:"))
    {
        return Ok(UriTarget::File(PathBuf::from(percent_decode(rest)?)));
    }
    if let Some((scheme, _)) = uri.split_once(':')
        && !scheme.contains('/')
    {
        return Err(format!(
            "unsupported URI scheme '{}:'",
            Untrusted::name(scheme)
        ));
    }
    Ok(UriTarget::File(base.join(percent_decode(uri)?)))
}

/// Decodes `%XX` escapes; the result must be UTF-8.
fn percent_decode(s: &str) -> Result<String, String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if b == b'%' {
            let hex = s
                .get(i + 1..i + 3)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("URI '{}' has a bad %-escape", Untrusted::name(s)))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(b);
            i += 1;
        }
    }
    String::from_utf8(out)
        .map_err(|_| format!("URI '{}' does not decode to UTF-8", Untrusted::name(s)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_relative_and_rejects_bad() {
        match resolve("a%20b.bin", Path::new("/x")).unwrap() {
            UriTarget::File(p) => assert_eq!(p, Path::new("/x/a b.bin")),
            UriTarget::Data => panic!("not data"),
        }
        assert!(resolve("a%FF.bin", Path::new("/x")).is_err());
        assert!(resolve("a%2.bin", Path::new("/x")).is_err());
        assert!(resolve("http://x/a.bin", Path::new("/x")).is_err());
        assert!(matches!(
            resolve("data:application/octet-stream;base64,AAAA", Path::new("/x")),
            Ok(UriTarget::Data)
        ));
    }
}
