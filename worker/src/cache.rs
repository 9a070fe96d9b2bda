//! The worker's content-addressed blob cache: in memory up to a byte budget, least recently used out first, and
//! optionally on disk up to a size cap, so a restarted worker need not be sent its blobs again.
//!
//! Blobs are immutable and named by the hash of their bytes, so a cached copy is never stale. The disk half is a
//! [`DiskStore`] of `ID.blob` files named by that hash: a file read back is hashed again before use, and a
//! damaged one is deleted, not rendered from.

use crate::disk_store::{DiskStore, DiskStoreError, Integrity};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// The extension of blob files on disk.
const EXTENSION: &str = "blob";

/// The file of a blob on disk.
fn file_name(id: &str) -> String {
    format!("{id}.{EXTENSION}")
}

/// Blobs by id.
pub struct BlobCache {
    memory: Mutex<Memory>,
    disk: Option<DiskStore>,
}

struct Memory {
    budget: u64,
    bytes: u64,
    /// id → (blob, last use).
    blobs: HashMap<String, (Arc<Vec<u8>>, u64)>,
    clock: u64,
}

impl BlobCache {
    /// A cache of `memory_budget` bytes in memory and, when given, a folder capped at the given bytes.
    pub fn new(memory_budget: u64, disk: Option<(PathBuf, u64)>) -> Result<Self, DiskStoreError> {
        let disk = match disk {
            Some((dir, cap)) => Some(DiskStore::open(dir, cap, &[EXTENSION], Integrity::NamedByHash)?),
            None => None,
        };
        let memory = Memory { budget: memory_budget, bytes: 0, blobs: HashMap::new(), clock: 0 };
        Ok(Self { memory: Mutex::new(memory), disk })
    }

    fn memory(&self) -> std::sync::MutexGuard<'_, Memory> {
        // A panic while holding the lock cannot leave the map half-updated in a way that matters here.
        self.memory.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Whether the blob is held, in memory or on disk.
    pub fn contains(&self, id: &str) -> bool {
        self.memory().blobs.contains_key(id) || self.disk.as_ref().is_some_and(|d| d.contains(&file_name(id)))
    }

    /// The blob's size in bytes, from memory or from its file on disk (which is not read); `None` when it is
    /// not held.
    pub fn size(&self, id: &str) -> Option<u64> {
        if let Some((blob, _)) = self.memory().blobs.get(id) {
            return Some(blob.len() as u64);
        }
        self.disk.as_ref()?.len(&file_name(id))
    }

    /// The blob, from memory or (checked again) from disk.
    pub fn get(&self, id: &str) -> Option<Arc<Vec<u8>>> {
        {
            let mut m = self.memory();
            m.clock += 1;
            let now = m.clock;
            if let Some((blob, used)) = m.blobs.get_mut(id) {
                *used = now;
                return Some(blob.clone());
            }
        }
        let bytes = match self.disk.as_ref()?.read(&file_name(id)) {
            Ok(bytes) => bytes?,
            Err(_) => {
                tracing::warn!(id, "cached blob on disk is damaged; deleting it");
                return None;
            }
        };
        let blob = Arc::new(bytes);
        self.insert_memory(id.to_owned(), blob.clone());
        Some(blob)
    }

    /// Stores a verified blob (its id must be the hash of its bytes).
    pub fn insert(&self, id: String, blob: Arc<Vec<u8>>) {
        if let Some(disk) = &self.disk
            && let Err(e) = disk.write(&file_name(&id), &blob)
        {
            tracing::warn!(id, "cannot keep the blob on disk: {e}");
        }
        self.insert_memory(id, blob);
    }

    fn insert_memory(&self, id: String, blob: Arc<Vec<u8>>) {
        let mut m = self.memory();
        m.clock += 1;
        let now = m.clock;
        let len = blob.len() as u64;
        if let Some((old, _)) = m.blobs.insert(id.clone(), (blob, now)) {
            m.bytes -= old.len() as u64;
        }
        m.bytes += len;
        // Evict the least recently used others until the budget holds (a blob larger than the budget stays alone).
        while m.bytes > m.budget {
            let Some(victim) =
                m.blobs.iter().filter(|(k, _)| **k != id).min_by_key(|(_, (_, used))| *used).map(|(k, _)| k.clone())
            else {
                break;
            };
            if let Some((b, _)) = m.blobs.remove(&victim) {
                m.bytes -= b.len() as u64;
            }
        }
    }

    /// Bytes held in memory.
    pub fn memory_bytes(&self) -> u64 {
        self.memory().bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(fill: u8, len: usize) -> (String, Arc<Vec<u8>>) {
        let b = vec![fill; len];
        (photon_proto::blob_id(&b), Arc::new(b))
    }

    #[test]
    fn memory_evicts_least_recently_used() {
        let cache = BlobCache::new(250, None).unwrap();
        let (a, ba) = blob(1, 100);
        let (b, bb) = blob(2, 100);
        let (c, bc) = blob(3, 100);
        cache.insert(a.clone(), ba);
        cache.insert(b.clone(), bb);
        assert!(cache.get(&a).is_some()); // a is now more recent than b
        cache.insert(c.clone(), bc);
        assert!(cache.contains(&a) && cache.contains(&c) && !cache.contains(&b));
        assert_eq!(cache.memory_bytes(), 200);
    }

    #[test]
    fn disk_survives_a_new_cache_and_damage_is_caught() {
        let dir = std::env::temp_dir().join(format!("photon-blob-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let (a, ba) = blob(7, 1000);
        BlobCache::new(1 << 20, Some((dir.clone(), 1 << 20))).unwrap().insert(a.clone(), ba.clone());
        let again = BlobCache::new(1 << 20, Some((dir.clone(), 1 << 20))).unwrap();
        assert!(again.contains(&a));
        // Its size from the file alone, then from memory once read.
        assert_eq!(again.size(&a), Some(1000));
        assert_eq!(again.get(&a).unwrap(), ba);
        assert_eq!(again.size(&a), Some(1000));
        assert_eq!(again.size(&blob(8, 10).0), None);
        // Damage the file: a fresh cache must refuse it and forget it.
        std::fs::write(dir.join(format!("{a}.blob")), b"not the blob").unwrap();
        let third = BlobCache::new(1 << 20, Some((dir.clone(), 1 << 20))).unwrap();
        assert!(third.get(&a).is_none());
        assert!(!third.contains(&a));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn disk_keeps_under_its_cap() {
        let dir = std::env::temp_dir().join(format!("photon-blob-cap-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let cache = BlobCache::new(1 << 20, Some((dir.clone(), 2500))).unwrap();
        for fill in 0..5u8 {
            let (id, b) = blob(fill, 1000);
            cache.insert(id, b);
        }
        let total: u64 = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum();
        assert!(total <= 2500, "{total} bytes on disk");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
