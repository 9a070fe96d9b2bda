//! Binary encoding of serialisable data: the one place that calls bincode.
//!
//! Every blob is `MAGIC` (4 bytes), the little-endian `u32` [`FORMAT_VERSION`], then the value in bincode 2's
//! standard configuration with fixed-width integers (so `u32` fields such as packed directions and indices
//! take 4 bytes, not up to 5, and a blob's size follows from its element counts). A blob written by another
//! format version is refused with [`CodecError::Version`] instead of being misread.
//!
//! [`decode`] refuses input longer than the caller's limit before reading it. Serde preallocates collections
//! from their encoded length only up to a small cap and then grows them as elements actually arrive, so a
//! forged length cannot make decoding allocate much more than a small multiple of the input's size.
//!
//! Content hashing of blobs belongs to whoever stores or ships them; this module only turns values into
//! bytes and back.

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Leading bytes of every blob.
pub const MAGIC: [u8; 4] = *b"PHTN";

/// Version of the blob format. Raise it whenever the encoding of any serialised type changes.
pub const FORMAT_VERSION: u32 = 5;

const HEADER_LEN: usize = MAGIC.len() + 4;

/// Why a value could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// The value could not be encoded.
    #[error("encoding failed: {0}")]
    Encode(#[from] bincode::error::EncodeError),
    /// The bytes are not a valid encoding of the expected type.
    #[error("decoding failed: {0}")]
    Decode(#[from] bincode::error::DecodeError),
    /// The input is larger than the caller allows.
    #[error("blob of {len} bytes exceeds the limit of {limit} bytes")]
    TooLarge {
        /// Length of the input in bytes.
        len: usize,
        /// The caller's limit in bytes.
        limit: usize,
    },
    /// The input does not start with [`MAGIC`] (or is shorter than the header).
    #[error("not a photon blob (bad magic or truncated header)")]
    BadMagic,
    /// The blob was written by a different format version.
    #[error("blob format version {found}, this build reads version {expected}")]
    Version {
        /// Version found in the blob.
        found: u32,
        /// Version this build reads and writes.
        expected: u32,
    },
    /// The value ended before the input did.
    #[error("{0} trailing bytes after the encoded value")]
    TrailingBytes(usize),
}

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_fixed_int_encoding()
}

/// Encodes `v` as a versioned blob.
pub fn encode<T: Serialize>(v: &T) -> Result<Vec<u8>, CodecError> {
    let mut out = Vec::with_capacity(HEADER_LEN + 64);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bincode::serde::encode_into_std_write(v, &mut out, config())?;
    Ok(out)
}

/// Decodes a blob written by [`encode`], refusing input longer than `limit` bytes.
pub fn decode<T: DeserializeOwned>(bytes: &[u8], limit: usize) -> Result<T, CodecError> {
    if bytes.len() > limit {
        return Err(CodecError::TooLarge { len: bytes.len(), limit });
    }
    let (header, body) = bytes.split_at_checked(HEADER_LEN).ok_or(CodecError::BadMagic)?;
    let (magic, version) = header.split_at(MAGIC.len());
    if magic != MAGIC {
        return Err(CodecError::BadMagic);
    }
    let found = u32::from_le_bytes([version[0], version[1], version[2], version[3]]);
    if found != FORMAT_VERSION {
        return Err(CodecError::Version { found, expected: FORMAT_VERSION });
    }
    let (value, read) = bincode::serde::decode_from_slice(body, config())?;
    if read != body.len() {
        return Err(CodecError::TrailingBytes(body.len() - read));
    }
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Sample {
        name: String,
        values: Vec<f32>,
        id: u32,
    }

    fn sample() -> Sample {
        Sample { name: "cornell".into(), values: vec![1.0, -0.5, f32::MIN_POSITIVE], id: 0xDEAD_BEEF }
    }

    #[test]
    fn round_trip() {
        let bytes = encode(&sample()).unwrap();
        assert_eq!(&bytes[..4], &MAGIC);
        let back: Sample = decode(&bytes, bytes.len()).unwrap();
        assert_eq!(back, sample());
    }

    #[test]
    fn integers_are_fixed_width() {
        // 4 (magic) + 4 (version) + 8 (len) + 7 (name) + 8 (len) + 12 (values) + 4 (id)
        assert_eq!(encode(&sample()).unwrap().len(), 47);
    }

    #[test]
    fn refuses_oversized_input() {
        let bytes = encode(&sample()).unwrap();
        let err = decode::<Sample>(&bytes, bytes.len() - 1).unwrap_err();
        assert!(matches!(err, CodecError::TooLarge { .. }), "{err}");
    }

    #[test]
    fn refuses_other_versions_magic_and_garbage() {
        let mut bytes = encode(&sample()).unwrap();
        bytes[4] ^= 0xFF;
        assert!(matches!(decode::<Sample>(&bytes, 1 << 20), Err(CodecError::Version { .. })));
        bytes[0] = b'X';
        assert!(matches!(decode::<Sample>(&bytes, 1 << 20), Err(CodecError::BadMagic)));
        assert!(matches!(decode::<Sample>(b"PHT", 1 << 20), Err(CodecError::BadMagic)));
        let good = encode(&sample()).unwrap();
        assert!(matches!(decode::<Sample>(&good[..good.len() - 2], 1 << 20), Err(CodecError::Decode(_))));
        let mut long = good.clone();
        long.push(0);
        assert!(matches!(decode::<Sample>(&long, 1 << 20), Err(CodecError::TrailingBytes(1))));
    }

    #[test]
    fn forged_length_does_not_allocate_it() {
        // A Vec<f32> claiming 2^60 elements in a 20-byte blob must fail cleanly, not try to allocate.
        let mut bytes = Vec::from(MAGIC);
        bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        bytes.extend_from_slice(&(1u64 << 60).to_le_bytes());
        bytes.extend_from_slice(&[0; 4]);
        assert!(matches!(decode::<Vec<f32>>(&bytes, 1 << 20), Err(CodecError::Decode(_))));
    }
}
