//! Arrays built in parallel chunks, joined in order.

use rayon::prelude::*;

/// `parts` joined in order, copied in parallel into the new array, and the index there of each part's first
/// item: item `i` comes from the last part whose first index is at most `i` (that part is not empty).
pub fn join<T: Copy + Send + Sync>(parts: &[&[T]]) -> (Vec<T>, Vec<usize>) {
    let mut firsts = Vec::with_capacity(parts.len());
    let mut total = 0usize;
    for p in parts {
        firsts.push(total);
        total += p.len();
    }
    let joined = (0..total)
        .into_par_iter()
        .with_min_len(1 << 12)
        .map(|i| {
            let c = firsts.partition_point(|&f| f <= i) - 1;
            parts[c][i - firsts[c]]
        })
        .collect();
    (joined, firsts)
}
