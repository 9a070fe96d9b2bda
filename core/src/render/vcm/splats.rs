//! Light-tracing splats, kept by band of image rows so that a pass adds them to its sums in parallel.
//!
//! A light subpath that connects to the camera leaves a splat: a pixel and the radiance it adds there. The
//! chunks of light subpaths traced in parallel each order their splats by band of [`BAND_COUNT`] (stably, by a
//! counting sort), and the bands are joined band after band. A pass then adds each band's splats to the sums
//! of its rows, the bands in parallel. The sums do not depend on the order: every value added is a
//! non-negative fixed-point integer and additions saturate, so each sum is `min(i64::MAX, exact sum)` in any
//! order; the order is fixed all the same.

use super::super::sums::add_fixed;
use super::join::join;
use crate::Rgb;
use rayon::prelude::*;
use std::ops::Range;

/// One light-tracing contribution: a pixel index (`y·width + x`) and radiance.
pub type Splat = (u32, Rgb);

/// The number of bands the image's rows are cut into (the last may be shorter; fewer when the image has fewer
/// rows): enough to keep every thread busy while adding, few enough that a chunk's counts stay small.
const BAND_COUNT: u32 = 64;

/// How an image of `width × height` pixels is cut into bands of whole rows.
#[derive(Clone, Copy, Debug)]
pub struct Bands {
    width: u32,
    /// Rows per band (at least 1).
    rows: u32,
    /// Number of bands.
    count: u32,
}

impl Bands {
    /// The bands of an image `width` pixels wide and `height` rows high.
    pub fn new(width: u32, height: u32) -> Self {
        let rows = height.div_ceil(BAND_COUNT).max(1);
        Self { width: width.max(1), rows, count: height.div_ceil(rows) }
    }

    /// The band of pixel index `pixel` (clamped to the last band).
    #[inline]
    fn of(&self, pixel: u32) -> usize {
        let band = u64::from(pixel) / (u64::from(self.width) * u64::from(self.rows));
        band.min(u64::from(self.count.saturating_sub(1))) as usize
    }
}

/// The splats of one chunk of light subpaths, in band order (subpath order within a band), and where each band
/// starts: band `b` is `splats[starts[b]..starts[b + 1]]`.
pub struct ChunkSplats {
    splats: Vec<Splat>,
    starts: Vec<usize>,
}

impl ChunkSplats {
    /// `splats` (in subpath order) ordered by band, stably (a counting sort).
    pub fn new(splats: &[Splat], bands: &Bands) -> Self {
        let mut starts = vec![0usize; bands.count as usize + 1];
        for &(pixel, _) in splats {
            starts[bands.of(pixel) + 1] += 1;
        }
        for b in 1..starts.len() {
            starts[b] += starts[b - 1];
        }
        let mut next = starts.clone();
        let mut sorted = vec![(0u32, Rgb::ZERO); splats.len()];
        for &s in splats {
            let b = bands.of(s.0);
            sorted[next[b]] = s;
            next[b] += 1;
        }
        Self { splats: sorted, starts }
    }

    fn band(&self, b: usize) -> &[Splat] {
        band(&self.splats, &self.starts, b)
    }
}

/// Band `b` of `splats`, whose bands start at `starts` (empty when `b` is past the last band).
fn band<'a>(splats: &'a [Splat], starts: &[usize], b: usize) -> &'a [Splat] {
    match (starts.get(b), starts.get(b + 1)) {
        (Some(&start), Some(&end)) => splats.get(start..end).unwrap_or(&[]),
        _ => &[],
    }
}

/// Every light-tracing splat of one iteration, band after band (chunk after chunk, in subpath order, within a
/// band).
pub struct Splats {
    bands: Bands,
    splats: Vec<Splat>,
    /// Band `b` is `splats[starts[b]..starts[b + 1]]`.
    starts: Vec<usize>,
}

impl Splats {
    /// The chunks' splats joined band after band, copied in parallel.
    pub fn join(chunks: &[&ChunkSplats], bands: Bands) -> Self {
        let parts: Vec<&[Splat]> =
            (0..bands.count as usize).flat_map(|b| chunks.iter().map(move |c| c.band(b))).collect();
        let (splats, firsts) = join(&parts);
        let mut starts: Vec<usize> = firsts.iter().step_by(chunks.len().max(1)).copied().collect();
        starts.resize(bands.count as usize, splats.len());
        starts.push(splats.len());
        Self { bands, splats, starts }
    }

    /// The number of splats.
    pub fn len(&self) -> usize {
        self.splats.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.splats.is_empty()
    }

    /// Adds the fixed-point value of each splat that lands in rows `rows` to `sums` (3 channels per pixel, row
    /// after row of `rows`), saturating; the bands in parallel.
    pub fn add_to(&self, rows: &Range<u32>, sums: &mut [i64]) {
        let (width, per_band) = (self.bands.width, self.bands.rows);
        let row_len = 3 * width as usize;
        // The block's rows cut where the bands are cut: (band, its first row here, its sums).
        let mut parts = Vec::new();
        let (mut rest, mut y) = (sums, rows.start);
        while y < rows.end && !rest.is_empty() {
            let end = ((y / per_band + 1) * per_band).min(rows.end);
            let (head, tail) = rest.split_at_mut(((end - y) as usize * row_len).min(rest.len()));
            parts.push(((y / per_band) as usize, y..end, head));
            (rest, y) = (tail, end);
        }
        parts.into_par_iter().for_each(|(b, band_rows, sums)| {
            for &(pixel, c) in band(&self.splats, &self.starts, b) {
                let y = pixel / width;
                if !band_rows.contains(&y) {
                    continue;
                }
                let at = 3 * ((y - band_rows.start) as usize * width as usize + (pixel % width) as usize);
                if let Some(px) = sums.get_mut(at..at + 3) {
                    add_fixed(px, c);
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::sums::to_fixed;
    use super::*;

    /// Splats of `chunks` chunks over a `width × height` image, some pixels hit many times.
    fn chunks(width: u32, height: u32, chunks: usize, per_chunk: usize) -> Vec<Vec<Splat>> {
        let mut state = 0x9e37_79b9_u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        (0..chunks)
            .map(|_| {
                (0..per_chunk)
                    .map(|_| {
                        let pixel = next() % (width * height);
                        let v = (next() % 1000) as f32 / 7.0;
                        (pixel, Rgb::new(v, 2.0 * v, 0.5))
                    })
                    .collect()
            })
            .collect()
    }

    /// The serial loop the bands replace: every splat in subpath order, added to the rows it lands in.
    fn serial(width: u32, rows: &Range<u32>, splats: &[Splat], sums: &mut [i64]) {
        for &(pixel, c) in splats {
            let y = pixel / width;
            if rows.contains(&y) {
                let at = 3 * ((y - rows.start) as usize * width as usize + (pixel % width) as usize);
                for (s, v) in sums[at..at + 3].iter_mut().zip(c.to_array()) {
                    *s = s.saturating_add(to_fixed(v));
                }
            }
        }
    }

    #[test]
    fn the_bands_add_what_the_serial_loop_adds_for_any_rows() {
        for (width, height) in [(7, 5), (33, 130), (16, 64), (1, 200)] {
            let parts = chunks(width, height, 5, 300);
            let bands = Bands::new(width, height);
            let chunk_splats: Vec<ChunkSplats> = parts.iter().map(|p| ChunkSplats::new(p, &bands)).collect();
            let splats = Splats::join(&chunk_splats.iter().collect::<Vec<_>>(), bands);
            let all: Vec<Splat> = parts.concat();
            assert_eq!(splats.len(), all.len());
            for rows in [0..height, 0..1, height / 3..height, height / 2..height / 2 + 3] {
                let len = 3 * width as usize * rows.len();
                // A camera value already in every pixel, as the pass leaves it.
                let (mut banded, mut expected) = (vec![5i64; len], vec![5i64; len]);
                splats.add_to(&rows, &mut banded);
                serial(width, &rows, &all, &mut expected);
                assert_eq!(banded, expected, "{width}×{height}, rows {rows:?}");
            }
        }
    }

    #[test]
    fn sums_that_saturate_do_so_in_any_order() {
        // 40 001 splats of at most 2⁴⁸ each pass i64::MAX = 2⁶³ − 1 after 2¹⁵ of them.
        let (width, height) = (4, 4);
        let bright = (5, Rgb::splat(MAX));
        let parts = [vec![bright; 20_000], vec![(5, Rgb::ONE)], vec![bright; 20_000]];
        let bands = Bands::new(width, height);
        let chunk_splats: Vec<ChunkSplats> = parts.iter().map(|p| ChunkSplats::new(p, &bands)).collect();
        let splats = Splats::join(&chunk_splats.iter().collect::<Vec<_>>(), bands);
        let mut sums = vec![0i64; 3 * 16];
        splats.add_to(&(0..height), &mut sums);
        assert_eq!(&sums[15..18], &[i64::MAX; 3]);
        assert!(sums.iter().enumerate().all(|(i, &s)| (15..18).contains(&i) || s == 0));
    }

    const MAX: f32 = crate::render::sums::MAX_UNIT_RADIANCE;

    #[test]
    fn an_image_of_few_rows_has_one_band_per_row() {
        let bands = Bands::new(10, 3);
        assert_eq!((bands.rows, bands.count), (1, 3));
        let bands = Bands::new(10, 1000);
        assert_eq!((bands.rows, bands.count), (16, 63));
        assert_eq!(bands.of(10 * 1000 - 1), 62);
    }
}
