//! Reading the files a scene refers to: with a size limit, and only data URIs or files
//! inside the scene's folder.
use crate::{Error, Result};
use base64::Engine;
use std::path::{Component, Path, PathBuf};

/// Largest scene, buffer or image file psrestir reads (bytes).
pub const MAX_FILE_BYTES: u64 = 4 << 30;

/// A whole file, refused past `MAX_FILE_BYTES`.
pub(super) fn read_file(path: &Path) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| Error::file(path, e.to_string()))?;
    if meta.len() > MAX_FILE_BYTES {
        return Err(Error::file(
            path,
            format!(
                "file is {} bytes, over the limit of {MAX_FILE_BYTES}",
                meta.len()
            ),
        ));
    }
    std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))
}

/// Bytes behind a URI of the scene at `path` (folder `base`): a base64 data URI or a file
/// inside the scene's folder; `what` names the referring object in errors.
pub(super) fn read_uri(path: &Path, base: &Path, uri: &str, what: &str) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (header, payload) = rest
            .split_once(',')
            .ok_or_else(|| Error::file(path, format!("{what}: malformed data URI")))?;
        if !header.ends_with(";base64") {
            return Err(Error::file(path, format!("{what}: data URI is not base64")));
        }
        return base64::engine::general_purpose::STANDARD
            .decode(payload.trim())
            .map_err(|e| Error::file(path, format!("{what}: bad base64 in data URI: {e}")));
    }
    let first_sep = uri.find('/').unwrap_or(uri.len());
    if uri[..first_sep].contains(':') {
        return Err(Error::file(
            path,
            format!(
            "{what}: URI `{uri}` refused: psrestir reads only files beside the scene and data URIs"
        ),
        ));
    }
    let rel = PathBuf::from(percent_decode(uri));
    if rel.is_absolute()
        || uri.starts_with('/')
        || uri.starts_with('\\')
        || rel
            .components()
            .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return Err(Error::file(
            path,
            format!("{what}: URI `{uri}` refused: it leaves the scene's folder"),
        ));
    }
    let full = base.join(&rel);
    // Symbolic links must not lead out of the folder either.
    if let (Ok(cb), Ok(cf)) = (base.canonicalize(), full.canonicalize()) {
        if !cf.starts_with(&cb) {
            return Err(Error::file(
                path,
                format!("{what}: URI `{uri}` refused: it resolves outside the scene's folder"),
            ));
        }
    }
    read_file(&full).map_err(|e| match e {
        Error::File { msg, .. } => Error::file(path, format!("{what} `{}`: {msg}", full.display())),
        other => other,
    })
}

/// `%XX` escapes of a URI decoded (invalid ones kept as they are).
pub(super) fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let hex = |c: u8| (c as char).to_digit(16).map(|d| d as u8);
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push(h * 16 + l);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}
