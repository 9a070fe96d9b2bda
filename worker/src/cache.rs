//! The worker's content-addressed blob cache: in memory up to a byte budget, least recently used out first, and
//! optionally on disk up to a size cap, so a restarted worker need not be sent its blobs again.
//!
//! Blobs are immutable and named by the hash of their bytes, so a cached copy is never stale. A file read back
//! from disk is hashed again before use: a damaged file is deleted, not rendered from.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// Blobs by id.
pub struct BlobCache {
    memory: Mutex<Memory>,
    disk: Option<Disk>,
}

struct Memory {
    budget: u64,
    bytes: u64,
    /// id → (blob, last use).
    blobs: HashMap<String, (Arc<Vec<u8>>, u64)>,
    clock: u64,
}

struct Disk {
    dir: PathBuf,
    cap: u64,
}

/// Why a cache cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// Its folder cannot be created.
    #[error("cannot create the cache folder {}: {cause}", dir.display())]
    CreateDir {
        /// The folder.
        dir: PathBuf,
        /// The reason.
        cause: std::io::Error,
    },
}

impl BlobCache {
    /// A cache of `memory_budget` bytes in memory and, when given, a folder capped at the given bytes.
    pub fn new(memory_budget: u64, disk: Option<(PathBuf, u64)>) -> Result<Self, CacheError> {
        let disk = match disk {
            Some((dir, cap)) => {
                std::fs::create_dir_all(&dir).map_err(|cause| CacheError::CreateDir { dir: dir.clone(), cause })?;
                Some(Disk { dir, cap })
            }
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
        self.memory().blobs.contains_key(id) || self.disk.as_ref().is_some_and(|d| d.path(id).is_file())
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
        let disk = self.disk.as_ref()?;
        let bytes = std::fs::read(disk.path(id)).ok()?;
        if photon_proto::blob_id(&bytes) != id {
            tracing::warn!(id, "cached blob on disk is damaged; deleting it");
            let _ = std::fs::remove_file(disk.path(id));
            return None;
        }
        let blob = Arc::new(bytes);
        self.insert_memory(id.to_owned(), blob.clone());
        Some(blob)
    }

    /// Stores a verified blob (its id must be the hash of its bytes).
    pub fn insert(&self, id: String, blob: Arc<Vec<u8>>) {
        if let Some(disk) = &self.disk
            && let Err(e) = disk.store(&id, &blob)
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

impl Disk {
    fn path(&self, id: &str) -> PathBuf {
        self.dir.join(format!("{id}.blob"))
    }

    /// Writes the blob (to a temporary name, then renamed, so a crash leaves no half file under the id) and
    /// removes the oldest files until the folder is under its cap.
    fn store(&self, id: &str, bytes: &[u8]) -> std::io::Result<()> {
        if bytes.len() as u64 > self.cap {
            return Ok(());
        }
        let tmp = self.dir.join(format!("{id}.tmp-{}", std::process::id()));
        std::fs::write(&tmp, bytes)?;
        std::fs::rename(&tmp, self.path(id))?;
        self.trim(id)
    }

    fn trim(&self, keep: &str) -> std::io::Result<()> {
        let mut files: Vec<(std::time::SystemTime, u64, PathBuf)> = Vec::new();
        for entry in std::fs::read_dir(&self.dir)? {
            let entry = entry?;
            let path = entry.path();
            if path.extension().is_some_and(|e| e == "blob") {
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
            if path.file_stem().is_some_and(|s| s == keep) {
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
        assert_eq!(again.get(&a).unwrap(), ba);
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
