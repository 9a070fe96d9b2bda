//! The bytes a glTF file points at: each buffer (the GLB's binary chunk, a `data:` URI in base64, or a file
//! beside the glTF) and each image (a buffer view or a URI). Files are read as meshes are, regular files only and
//! within `[limits] mesh_mib`; every buffer must hold the bytes its `byteLength` promises, so an accessor that
//! the crate checked against the buffer views never reads past the data.

use super::types::{Import, malformed};
use crate::geometry::mesh::MeshError;
use std::path::{Path, PathBuf};

/// The data of every buffer, by index, each at least as long as its `byteLength`.
pub(super) fn load(gltf: &gltf::Gltf, file: &Path, limit: u64) -> Result<Vec<Vec<u8>>, MeshError> {
    let mut out = Vec::new();
    for b in gltf.document.buffers() {
        let data = match b.source() {
            gltf::buffer::Source::Bin => gltf.blob.clone().ok_or_else(|| {
                malformed(file, format!("buffers[{}] is the GLB binary chunk, but the file has none", b.index()))
            })?,
            gltf::buffer::Source::Uri(uri) => uri_bytes(uri, file, limit, &format!("buffers[{}]", b.index()))?,
        };
        if data.len() < b.length() {
            return Err(malformed(
                file,
                format!(
                    "buffers[{}] holds {} bytes, but its byteLength is {} (a truncated file?)",
                    b.index(),
                    data.len(),
                    b.length()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// The encoded bytes of image `index` (a buffer view or a URI), with a name for messages.
pub(super) fn image_bytes(
    im: &Import<'_>,
    image: &gltf::Image<'_>,
    limit: u64,
) -> Result<(Vec<u8>, PathBuf), MeshError> {
    let field = format!("images[{}]", image.index());
    match image.source() {
        gltf::image::Source::View { view, .. } => {
            let data = im.buffers.get(view.buffer().index()).map(Vec::as_slice).unwrap_or_default();
            let bytes = data.get(view.offset()..view.offset() + view.length()).ok_or_else(|| {
                malformed(im.file, format!("{field}: bufferViews[{}] reaches past its buffer", view.index()))
            })?;
            Ok((bytes.to_vec(), PathBuf::from(format!("{}#{field}", im.file.display()))))
        }
        gltf::image::Source::Uri { uri, .. } => {
            let bytes = uri_bytes(uri, im.file, limit, &field)?;
            let name = match uri.strip_prefix("data:") {
                Some(_) => PathBuf::from(format!("{}#{field}", im.file.display())),
                None => resolve(im.file, uri),
            };
            Ok((bytes, name))
        }
    }
}

/// The files beside the glTF that its buffers and images name (not `data:` URIs), for cache keys.
pub(super) fn external_files(doc: &gltf::Document, file: &Path) -> Vec<PathBuf> {
    let buffers = doc.buffers().filter_map(|b| match b.source() {
        gltf::buffer::Source::Uri(uri) => Some(uri.to_owned()),
        gltf::buffer::Source::Bin => None,
    });
    let images = doc.images().filter_map(|i| match i.source() {
        gltf::image::Source::Uri { uri, .. } => Some(uri.to_owned()),
        gltf::image::Source::View { .. } => None,
    });
    buffers.chain(images).filter(|u| !u.starts_with("data:")).map(|u| resolve(file, &u)).collect()
}

/// The bytes of a URI: a `data:` URI's base64 payload, or a relative file beside the glTF.
fn uri_bytes(uri: &str, file: &Path, limit: u64, field: &str) -> Result<Vec<u8>, MeshError> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (header, payload) = rest
            .split_once(',')
            .ok_or_else(|| malformed(file, format!("{field}: a data: URI without a comma before its payload")))?;
        if !header.ends_with(";base64") {
            return Err(malformed(file, format!("{field}: a data: URI must be base64 (`;base64,`)")));
        }
        return base64(payload).ok_or_else(|| malformed(file, format!("{field}: the data: URI is not valid base64")));
    }
    if uri.contains("://") {
        return Err(malformed(
            file,
            format!("{field}: `{}` is not a relative file: only local files are read", excerpt(uri)),
        ));
    }
    let path = resolve(file, uri);
    crate::input::read_regular(&path, limit, "limits.mesh_mib in the scene")
        .map_err(|source| MeshError::Io { file: path, source })
}

/// A relative URI resolved against the glTF's folder, its `%20`-style escapes decoded.
fn resolve(file: &Path, uri: &str) -> PathBuf {
    file.parent().unwrap_or(Path::new("")).join(percent_decode(uri))
}

fn excerpt(s: &str) -> String {
    crate::input::excerpt(s).to_string()
}

/// `%XX` escapes decoded (URIs in glTF are URI-encoded); a malformed escape is kept as written.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (b[i], b.get(i + 1).copied().and_then(hex), b.get(i + 2).copied().and_then(hex)) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, _, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Standard base64 (RFC 4648 §4, `=` padding optional), or `None` on any other character.
fn base64(s: &str) -> Option<Vec<u8>> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let s = s.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    for chunk in s.chunks(4) {
        let mut acc = 0u32;
        for (k, &c) in chunk.iter().enumerate() {
            acc |= value(c)? << (18 - 6 * k);
        }
        let bytes = acc.to_be_bytes();
        match chunk.len() {
            4 => out.extend_from_slice(&bytes[1..4]),
            3 => out.extend_from_slice(&bytes[1..3]),
            2 => out.push(bytes[1]),
            _ => return None,
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_and_escapes() {
        assert_eq!(base64("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64("aGVsbG8").unwrap(), b"hello");
        assert_eq!(base64("AAECAw==").unwrap(), [0, 1, 2, 3]);
        assert_eq!(base64("").unwrap(), b"");
        assert!(base64("a*b=").is_none() && base64("a").is_none());
        assert_eq!(percent_decode("my%20file.bin"), "my file.bin");
        assert_eq!(percent_decode("100%"), "100%");
    }
}
