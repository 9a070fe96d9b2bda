//! Reading the files a scene names (the scene file, its meshes) as a careless or hostile user may give them:
//! only regular files (a FIFO would block for ever, `/dev/zero` never ends, a folder is no file), no more than
//! a size cap, and text whose encoding errors are reported with their line and byte offset. Error messages
//! quote at most [`EXCERPT_CHARS`] characters of the input ([`excerpt`]).

use std::io::Read;
use std::path::Path;

/// The largest scene file read, in bytes: a scene is a few kilobytes of TOML (the geometry is in meshes).
pub const MAX_SCENE_BYTES: u64 = 16 << 20;

/// The default size cap of a mesh file, in MiB (`[limits] mesh_mib` in a scene).
pub const DEFAULT_MESH_MIB: u64 = 2048;

/// The default cap on a texture image, in MiB (`limits.texture_mib`), both its file and its decoded texels.
pub const DEFAULT_TEXTURE_MIB: u64 = 1024;

/// How many characters of the input an error message quotes.
pub const EXCERPT_CHARS: usize = 200;

/// Why a file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The operating system refused.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The path names something that is not a regular file.
    #[error("not a regular file but {0}: only regular files are read")]
    NotRegular(&'static str),
    /// The file is larger than the cap.
    #[error("larger than the limit of {limit} bytes ({setting})")]
    TooLarge {
        /// The cap in bytes.
        limit: u64,
        /// The setting that raises it.
        setting: &'static str,
    },
}

/// The bytes of the regular file `path`, refusing anything else (checked before opening it, so a FIFO is never
/// opened) and refusing more than `limit` bytes (also while reading, in case the file grows); `setting` names
/// what raises the limit.
pub fn read_regular(path: &Path, limit: u64, setting: &'static str) -> Result<Vec<u8>, InputError> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(InputError::NotRegular(kind(&meta.file_type())));
    }
    if meta.len() > limit {
        return Err(InputError::TooLarge { limit, setting });
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    std::fs::File::open(path)?.take(limit.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(InputError::TooLarge { limit, setting });
    }
    Ok(bytes)
}

/// What kind of thing a file type that is not a regular file names.
fn kind(t: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() { "a folder" } else { "neither a file nor a folder" }
}

/// Where text stops being UTF-8.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: not UTF-8 (byte offset {offset})")]
pub struct EncodingError {
    /// The line (1-based).
    pub line: usize,
    /// The offset of the first invalid byte in the file.
    pub offset: usize,
}

/// `bytes` as UTF-8 text, or the line and byte offset of its first invalid byte.
pub fn utf8(bytes: &[u8]) -> Result<&str, EncodingError> {
    std::str::from_utf8(bytes).map_err(|e| {
        let offset = e.valid_up_to();
        EncodingError { line: 1 + bytes[..offset].iter().filter(|&&b| b == b'\n').count(), offset }
    })
}

/// At most [`EXCERPT_CHARS`] characters of `text`, with `…` and the count of the bytes left out when it is
/// longer: what an error message may quote of the input.
pub fn excerpt(text: &str) -> String {
    match text.char_indices().nth(EXCERPT_CHARS) {
        None => text.to_owned(),
        Some((cut, _)) => format!("{}… ({} more bytes)", &text[..cut], text.len() - cut),
    }
}

/// Every line of `message` cut to an [`excerpt`]: a parser's message that quotes a line of the input.
pub fn excerpt_lines(message: &str) -> String {
    message.lines().map(excerpt).collect::<Vec<_>>().join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoding_errors_name_line_and_offset() {
        assert_eq!(utf8(b"a\nb\n# caf\xe9\n"), Err(EncodingError { line: 3, offset: 9 }));
        assert_eq!(utf8(b"fine\n"), Ok("fine\n"));
    }

    #[test]
    fn excerpts_are_short() {
        assert_eq!(excerpt("short"), "short");
        let long = "é".repeat(10_000);
        let e = excerpt(&long);
        assert!(e.chars().count() < EXCERPT_CHARS + 30 && e.ends_with("(19600 more bytes)"), "{e}");
    }

    #[test]
    fn only_regular_files_within_the_limit_are_read() {
        let dir = std::env::temp_dir().join(format!("photon-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let e = read_regular(&dir, 100, "x").unwrap_err();
        assert!(matches!(e, InputError::NotRegular("a folder")), "{e}");
        let file = dir.join("f");
        std::fs::write(&file, [0u8; 101]).unwrap();
        assert!(matches!(read_regular(&file, 100, "x"), Err(InputError::TooLarge { limit: 100, .. })));
        assert_eq!(read_regular(&file, 101, "x").unwrap().len(), 101);
        #[cfg(unix)]
        assert!(matches!(read_regular(Path::new("/dev/zero"), 100, "x"), Err(InputError::NotRegular("a device"))));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
