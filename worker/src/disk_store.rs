//! A folder of files kept under a size cap, oldest out first, each checked again when read back: the disk half
//! of the worker's blob cache and the coordinator's prepared-blob cache.
//!
//! Files are written under a temporary name and renamed, so a crash leaves no half file under a real name; the
//! folder is then trimmed to its cap by deleting the files with the oldest modification time (the file just
//! written is kept). A reader that wants least-recently-used order marks a file used with [`DiskStore::touch`].
//! A file that fails its check is deleted, never handed out. Only files whose extension is one of the store's
//! kinds count towards the cap, so two stores may not share a folder unless their kinds differ.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// How a stored file proves, when read back, that it holds what was written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Integrity {
    /// The file holds the bytes alone, and its name without the extension is their blob id
    /// ([`photon_proto::blob_id`]): content-addressed blobs.
    NamedByHash,
    /// The file holds the 32-byte checksum of the bytes ([`photon_proto::checksum`]), then the bytes.
    ChecksumHeader,
}

/// Why a store cannot be used or a file cannot be read back.
#[derive(Debug, thiserror::Error)]
pub enum DiskStoreError {
    /// The folder cannot be created.
    #[error("cannot create the cache folder {}: {cause}", dir.display())]
    CreateDir {
        /// The folder.
        dir: PathBuf,
        /// The reason.
        cause: std::io::Error,
    },
    /// The file failed its check and was deleted.
    #[error("{} is damaged", path.display())]
    Damaged {
        /// The file.
        path: PathBuf,
    },
}

/// A capped folder of files (see the module documentation).
#[derive(Debug)]
pub struct DiskStore {
    dir: PathBuf,
    cap: u64,
    kinds: &'static [&'static str],
    integrity: Integrity,
}

const HEADER: usize = 32;

impl DiskStore {
    /// The store in `dir`, created if missing, holding at most `cap` bytes of files whose extension is one of
    /// `kinds`.
    pub fn open(
        dir: PathBuf,
        cap: u64,
        kinds: &'static [&'static str],
        integrity: Integrity,
    ) -> Result<Self, DiskStoreError> {
        std::fs::create_dir_all(&dir).map_err(|cause| DiskStoreError::CreateDir { dir: dir.clone(), cause })?;
        Ok(Self { dir, cap, kinds, integrity })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The path of the file `name` (`stem.kind`).
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// Whether a file `name` is present (it is checked only when read).
    pub fn contains(&self, name: &str) -> bool {
        self.path(name).is_file()
    }

    /// The length of the bytes [`DiskStore::read`] would return for `name` (without its check), from the file's
    /// size; `None` when there is no such file.
    pub fn len(&self, name: &str) -> Option<u64> {
        let len = std::fs::metadata(self.path(name)).ok().filter(|m| m.is_file())?.len();
        Some(match self.integrity {
            Integrity::NamedByHash => len,
            Integrity::ChecksumHeader => len.saturating_sub(HEADER as u64),
        })
    }

    /// The bytes of `name`: `Ok(None)` when there is no such file (or it cannot be read), an error when it
    /// failed its check (it is deleted).
    pub fn read(&self, name: &str) -> Result<Option<Vec<u8>>, DiskStoreError> {
        let path = self.path(name);
        let Ok(mut bytes) = std::fs::read(&path) else { return Ok(None) };
        let intact = match self.integrity {
            Integrity::NamedByHash => {
                Path::new(name).file_stem().is_some_and(|stem| stem == photon_proto::blob_id(&bytes).as_str())
            }
            Integrity::ChecksumHeader => {
                bytes.len() >= HEADER && bytes[..HEADER] == photon_proto::checksum(&bytes[HEADER..])
            }
        };
        if !intact {
            let _ = std::fs::remove_file(&path);
            return Err(DiskStoreError::Damaged { path });
        }
        if self.integrity == Integrity::ChecksumHeader {
            bytes.drain(..HEADER);
        }
        Ok(Some(bytes))
    }

    /// Marks `name` used now, so trimming removes it after the files used less recently.
    pub fn touch(&self, name: &str) {
        if let Ok(f) = std::fs::File::options().append(true).open(self.path(name)) {
            let _ = f.set_modified(SystemTime::now());
        }
    }

    /// Writes `bytes` as `name` and trims the folder to its cap. A file that would exceed the cap alone is not
    /// written.
    pub fn write(&self, name: &str, bytes: &[u8]) -> std::io::Result<()> {
        let header = match self.integrity {
            Integrity::NamedByHash => None,
            Integrity::ChecksumHeader => Some(photon_proto::checksum(bytes)),
        };
        let len = bytes.len() + header.map_or(0, |h| h.len());
        if len as u64 > self.cap {
            return Ok(());
        }
        let tmp = self.dir.join(format!("{name}.tmp-{}", std::process::id()));
        match header {
            Some(h) => std::fs::write(&tmp, [h.as_slice(), bytes].concat())?,
            None => std::fs::write(&tmp, bytes)?,
        }
        std::fs::rename(&tmp, self.path(name))?;
        self.trim(name)
    }

    /// Deletes the oldest files of the store's kinds, except `keep`, until their total is within the cap.
    fn trim(&self, keep: &str) -> std::io::Result<()> {
        let mut files: Vec<(SystemTime, u64, PathBuf)> = Vec::new();
        for entry in std::fs::read_dir(&self.dir)? {
            let entry = entry?;
            let path = entry.path();
            if path.extension().is_some_and(|e| self.kinds.iter().any(|k| e == *k)) {
                let meta = entry.metadata()?;
                files.push((meta.modified()?, meta.len(), path));
            }
        }
        let mut total: u64 = files.iter().map(|f| f.1).sum();
        files.sort();
        for (_, len, path) in files {
            if total <= self.cap {
                break;
            }
            if path.file_name().is_some_and(|n| n == keep) {
                continue;
            }
            std::fs::remove_file(&path)?;
            total -= len;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn temp(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("photon-disk-store-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    /// Sets a file's modification time `age_s` seconds in the past, so tests need not sleep.
    fn age(store: &DiskStore, name: &str, age_s: u64) {
        let f = std::fs::File::options().append(true).open(store.path(name)).unwrap();
        f.set_modified(SystemTime::now() - Duration::from_secs(age_s)).unwrap();
    }

    /// A content-addressed store in `dir` holding `payload`, and the payload's file name.
    fn hashed_payload(dir: &Path) -> (DiskStore, String) {
        let store = DiskStore::open(dir.to_path_buf(), 1 << 20, &["blob"], Integrity::NamedByHash).unwrap();
        let name = format!("{}.blob", photon_proto::blob_id(b"payload"));
        store.write(&name, b"payload").unwrap();
        (store, name)
    }

    #[test]
    fn stores_and_reads_back_with_either_check() {
        let dir = temp("round-trip");
        let (hashed, name) = hashed_payload(&dir);
        assert!(hashed.contains(&name));
        assert_eq!(hashed.read(&name).unwrap().unwrap(), b"payload");
        assert_eq!(std::fs::read(hashed.path(&name)).unwrap(), b"payload", "no header on a hash-named file");
        let headed = DiskStore::open(dir.clone(), 1 << 20, &["scene"], Integrity::ChecksumHeader).unwrap();
        headed.write("k.scene", b"payload").unwrap();
        assert_eq!(headed.read("k.scene").unwrap().unwrap(), b"payload");
        assert_eq!(std::fs::metadata(headed.path("k.scene")).unwrap().len(), 32 + 7);
        assert!(headed.read("missing.scene").unwrap().is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_damaged_file_is_rejected_and_deleted() {
        let dir = temp("damage");
        let (hashed, name) = hashed_payload(&dir);
        std::fs::write(hashed.path(&name), b"not the payload").unwrap();
        assert!(matches!(hashed.read(&name), Err(DiskStoreError::Damaged { .. })));
        assert!(!hashed.contains(&name));
        let headed = DiskStore::open(dir.clone(), 1 << 20, &["scene"], Integrity::ChecksumHeader).unwrap();
        headed.write("k.scene", b"payload").unwrap();
        let mut bytes = std::fs::read(headed.path("k.scene")).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(headed.path("k.scene"), bytes).unwrap();
        assert!(matches!(headed.read("k.scene"), Err(DiskStoreError::Damaged { .. })));
        std::fs::write(headed.path("short.scene"), b"short").unwrap();
        assert!(headed.read("short.scene").is_err(), "a file shorter than its header is damaged");
        assert!(!headed.contains("k.scene") && !headed.contains("short.scene"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn trimming_removes_the_oldest_first_and_keeps_the_new_file() {
        let dir = temp("trim");
        let store = DiskStore::open(dir.clone(), 3500, &["a", "b"], Integrity::ChecksumHeader).unwrap();
        for (i, name) in ["0.a", "1.b", "2.a"].iter().enumerate() {
            store.write(name, &[0u8; 968]).unwrap(); // 1000 bytes with the header
            age(&store, name, 100 - 10 * i as u64);
        }
        // Used recently: outlives a newer file that was not.
        store.touch("0.a");
        // Not of the store's kinds: neither counted nor removed.
        std::fs::write(dir.join("other.c"), [0u8; 5000]).unwrap();
        store.write("3.b", &[0u8; 968]).unwrap();
        let left: Vec<bool> = ["0.a", "1.b", "2.a", "3.b"].iter().map(|n| store.contains(n)).collect();
        assert_eq!(left, [true, false, true, true]);
        assert!(dir.join("other.c").is_file());
        // A file larger than the cap alone is not written, and removes nothing.
        store.write("big.a", &[0u8; 3500]).unwrap();
        assert!(!store.contains("big.a") && store.contains("0.a") && store.contains("2.a") && store.contains("3.b"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_file_just_written_is_kept_even_when_it_is_not_the_newest() {
        let dir = temp("keep");
        let store = DiskStore::open(dir.clone(), 1500, &["blob"], Integrity::NamedByHash).unwrap();
        let (a, b) = (vec![1u8; 1000], vec![2u8; 1000]);
        let name = |bytes: &[u8]| format!("{}.blob", photon_proto::blob_id(bytes));
        store.write(&name(&a), &a).unwrap();
        // A clock that runs backwards (or a coarse one) must not make the store delete what it just wrote.
        let future = SystemTime::now() + Duration::from_secs(3600);
        std::fs::File::options().append(true).open(store.path(&name(&a))).unwrap().set_modified(future).unwrap();
        store.write(&name(&b), &b).unwrap();
        assert!(store.contains(&name(&b)) && !store.contains(&name(&a)));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
