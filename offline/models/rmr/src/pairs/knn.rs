//! Exact k-nearest-neighbour search over rows of features (squared Euclidean distance).
//!
//! Brute force with early termination: a candidate's distance is summed in blocks and
//! abandoned once it exceeds the current k-th best. Floating-point addition of non-negative
//! terms never decreases a partial sum, so an abandoned candidate could not have entered the
//! result: the search returns exactly what a full sort returns ([`k_nearest_brute_force`],
//! checked in the tests), including the tie order (by row index).

/// One result of a search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbour {
    /// Row index.
    pub index: usize,
    /// Squared Euclidean distance to the query.
    pub distance: f32,
}

const LANES: usize = 8;
const BLOCK: usize = 32;

/// Squared distance between `a` and `b`, or `None` as soon as a partial sum exceeds `bound`.
/// The summation order is fixed (8 lanes, lanes added in order), so the value does not depend
/// on `bound`.
#[inline]
pub fn distance_bounded(a: &[f32], b: &[f32], bound: f32) -> Option<f32> {
    debug_assert_eq!(a.len(), b.len());
    let mut acc = [0.0f32; LANES];
    let total = |acc: &[f32; LANES]| acc.iter().fold(0.0f32, |s, v| s + v);
    for (ab, bb) in a.chunks(BLOCK).zip(b.chunks(BLOCK)) {
        let (mut xa, mut xb) = (ab.chunks_exact(LANES), bb.chunks_exact(LANES));
        for (x, y) in (&mut xa).zip(&mut xb) {
            for l in 0..LANES {
                let d = x[l] - y[l];
                acc[l] += d * d;
            }
        }
        for (l, (x, y)) in xa.remainder().iter().zip(xb.remainder()).enumerate() {
            let d = x - y;
            acc[l] += d * d;
        }
        if total(&acc) > bound {
            return None;
        }
    }
    Some(total(&acc))
}

/// The `k` rows of `features` (`dim` values each) nearest to `query`, ascending by
/// (distance, index), skipping rows for which `skip(index)` is true. Fewer than `k` when fewer
/// rows remain.
pub fn k_nearest(
    features: &[f32],
    dim: usize,
    query: &[f32],
    k: usize,
    skip: impl Fn(usize) -> bool,
) -> Vec<Neighbour> {
    assert_eq!(query.len(), dim, "the query must have the database's feature size");
    let mut best: Vec<Neighbour> = Vec::with_capacity(k + 1);
    if k == 0 {
        return best;
    }
    for (index, row) in features.chunks_exact(dim).enumerate() {
        if skip(index) {
            continue;
        }
        let bound = if best.len() == k { best[k - 1].distance } else { f32::INFINITY };
        let Some(distance) = distance_bounded(row, query, bound) else { continue };
        if best.len() == k && distance >= bound {
            continue; // equal distance: the earlier index wins
        }
        let at = best.partition_point(|n| n.distance <= distance);
        best.insert(at, Neighbour { index, distance });
        best.truncate(k);
    }
    best
}

/// Reference for [`k_nearest`]: every distance, then a full sort by (distance, index).
pub fn k_nearest_brute_force(
    features: &[f32],
    dim: usize,
    query: &[f32],
    k: usize,
    skip: impl Fn(usize) -> bool,
) -> Vec<Neighbour> {
    let mut all: Vec<Neighbour> = features
        .chunks_exact(dim)
        .enumerate()
        .filter(|(i, _)| !skip(*i))
        .map(|(index, row)| Neighbour { index, distance: distance_bounded(row, query, f32::INFINITY).unwrap() })
        .collect();
    all.sort_by(|a, b| a.distance.total_cmp(&b.distance).then(a.index.cmp(&b.index)));
    all.truncate(k);
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::rng::SplitMix64;

    #[test]
    fn matches_brute_force_with_ties_and_exclusions() {
        let mut rng = SplitMix64::new(7);
        for (rows, dim) in [(500, 3), (300, 70), (64, 129)] {
            // Coarse values make exact ties common.
            let mut features: Vec<f32> = (0..rows * dim).map(|_| (rng.below(5) as f32) * 0.5).collect();
            // Duplicate a few rows exactly.
            for r in 0..10 {
                let (src, dst) = (r * 3, rows - 1 - r);
                let row = features[src * dim..(src + 1) * dim].to_vec();
                features[dst * dim..(dst + 1) * dim].copy_from_slice(&row);
            }
            for q in 0..20 {
                let query: Vec<f32> = if q % 2 == 0 {
                    features[(q * 7 % rows) * dim..(q * 7 % rows + 1) * dim].to_vec()
                } else {
                    (0..dim).map(|_| rng.range(0.0, 2.0) as f32).collect()
                };
                for k in [1, 5, 10, rows + 3] {
                    let skip = |i: usize| i % 7 == q % 7;
                    let fast = k_nearest(&features, dim, &query, k, skip);
                    let slow = k_nearest_brute_force(&features, dim, &query, k, skip);
                    assert_eq!(fast, slow, "rows {rows} dim {dim} query {q} k {k}");
                    let kept = (0..rows).filter(|&i| !skip(i)).count();
                    assert_eq!(fast.len(), k.min(kept));
                    assert!(fast.iter().all(|n| !skip(n.index)));
                }
            }
        }
    }

    #[test]
    fn bounded_distance_is_exact_or_abandoned() {
        let a = [1.0f32; 100];
        let b = [0.0f32; 100];
        assert_eq!(distance_bounded(&a, &b, f32::INFINITY), Some(100.0));
        assert_eq!(distance_bounded(&a, &b, 100.0), Some(100.0));
        assert_eq!(distance_bounded(&a, &b, 50.0), None);
        assert!(k_nearest(&a, 100, &b, 0, |_| false).is_empty());
    }
}
