//! Test-only fault injection, compiled only with the cargo feature `fault-injection`: a worker that commits a
//! chosen fault ([`Fault`]) lets the end-to-end tests prove that the coordinator catches it. The render and blob
//! paths call the [`Injector`]'s hooks under the same feature, so a worker built without it (a release binary)
//! has no fault code in them.

use photon_proto::pb;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};
use tonic::Status;

/// Faults a test can make a worker commit, to prove the coordinator catches them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Fault {
    /// Behave.
    #[default]
    None,
    /// Change one pixel of each of the first `n` strips after computing their checksum, as a bit flip in
    /// memory or on the wire would.
    CorruptPixels(u32),
    /// Wait this many milliseconds before each strip, as a much slower machine would take longer.
    Delay(u64),
    /// Render a NaN into the first pixel of every strip before computing the checksum, as a bug in an
    /// integrator would.
    NanPixels,
    /// Panic while rendering the first `n` strips, as a bug would.
    Panic(u32),
    /// Serve blobs to peers (`GetBlob`) with the first byte changed, as a bit flip would.
    CorruptBlobs,
}

/// A worker's fault and the strips it has left to commit it in.
#[derive(Debug)]
pub(crate) struct Injector {
    fault: Fault,
    /// Strips left to corrupt ([`Fault::CorruptPixels`]) or to panic in ([`Fault::Panic`]).
    left: AtomicU32,
}

impl Injector {
    /// The injector of `fault`.
    pub(crate) fn new(fault: Fault) -> Self {
        let left = match fault {
            Fault::CorruptPixels(n) | Fault::Panic(n) => n,
            Fault::None | Fault::Delay(_) | Fault::NanPixels | Fault::CorruptBlobs => 0,
        };
        Self { fault, left: AtomicU32::new(left) }
    }

    /// Takes one of the strips left, false when none is left.
    fn take_one(&self) -> bool {
        self.left.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1)).is_ok()
    }

    /// Before strip `strip` renders: panics ([`Fault::Panic`]), or waits ([`Fault::Delay`]) in small steps, so a
    /// strip whose coordinator left (`cancelled`) stops waiting and ends `CANCELLED`.
    pub(crate) fn before_render(&self, strip: u32, cancelled: &dyn Fn() -> bool) -> Result<(), Status> {
        match self.fault {
            Fault::Panic(_) if self.take_one() => panic!("fault injection: a panic while rendering strip {strip}"),
            Fault::Delay(ms) => {
                let end = Instant::now() + Duration::from_millis(ms);
                while Instant::now() < end {
                    if cancelled() {
                        return Err(Status::cancelled("the coordinator cancelled the strip"));
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// A strip's sums before their checksum: with [`Fault::NanPixels`] the first is impossible (negative), as
    /// a NaN in an integrator's estimate would make it.
    pub(crate) fn before_checksum(&self, strip: u32, mut sums: Vec<i64>) -> Vec<i64> {
        if self.fault == Fault::NanPixels
            && let Some(v) = sums.first_mut()
        {
            tracing::warn!(strip, "fault injection: an impossible sum before the checksum");
            *v = -1;
        }
        sums
    }

    /// A strip's bytes after their checksum: with [`Fault::CorruptPixels`], one bit of the first of the
    /// first `n` strips changes.
    pub(crate) fn after_checksum(&self, strip: u32, mut bytes: Vec<u8>) -> Vec<u8> {
        if matches!(self.fault, Fault::CorruptPixels(_)) && self.take_one() && bytes.len() >= 4 {
            tracing::warn!(strip, "fault injection: corrupting a pixel after the checksum");
            bytes[0] ^= 0x40;
        }
        bytes
    }

    /// The chunks of a blob served to a peer: with [`Fault::CorruptBlobs`], the first byte changes.
    pub(crate) fn served_chunks<I>(&self, chunks: I) -> impl Iterator<Item = pb::BlobChunk> + use<I>
    where
        I: Iterator<Item = pb::BlobChunk>,
    {
        let corrupt = self.fault == Fault::CorruptBlobs;
        chunks.enumerate().map(move |(i, mut chunk)| {
            if corrupt && i == 0 && !chunk.data.is_empty() {
                chunk.data[0] ^= 1;
            }
            chunk
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn panics_and_corruptions_count_down_from_n() {
        let corrupt = Injector::new(Fault::CorruptPixels(2));
        let bytes = |i: &Injector| i.after_checksum(0, vec![0; 8])[0];
        assert_eq!([bytes(&corrupt), bytes(&corrupt), bytes(&corrupt)], [0x40, 0x40, 0]);
        let panics = Injector::new(Fault::Panic(1));
        let first = std::panic::catch_unwind(|| panics.before_render(0, &|| false));
        assert!(first.is_err());
        assert!(panics.before_render(1, &|| false).is_ok());
        // A panicking worker corrupts nothing: the count is the panics'.
        assert_eq!(Injector::new(Fault::Panic(3)).after_checksum(0, vec![0; 8])[0], 0);
    }

    #[test]
    fn a_cancelled_delay_stops_waiting() {
        let slow = Injector::new(Fault::Delay(60_000));
        let t0 = Instant::now();
        let e = slow.before_render(0, &|| true).unwrap_err();
        assert_eq!(e.code(), tonic::Code::Cancelled);
        assert!(t0.elapsed() < Duration::from_secs(5));
    }

    #[test]
    fn nan_and_blob_faults_touch_only_the_first_value() {
        assert_eq!(Injector::new(Fault::NanPixels).before_checksum(0, vec![5, 6]), [-1, 6]);
        assert_eq!(Injector::new(Fault::None).before_checksum(0, vec![5, 6]), [5, 6]);
        let chunk = |b: u8| pb::BlobChunk { header: None, data: vec![b; 2] };
        let served: Vec<_> =
            Injector::new(Fault::CorruptBlobs).served_chunks([chunk(0), chunk(0)].into_iter()).collect();
        assert_eq!((served[0].data.as_slice(), served[1].data.as_slice()), (&[1, 0][..], &[0, 0][..]));
    }
}
