//! Grid lines of a drawing: the multiples of a step inside an interval, counted before they are
//! drawn. A loop that adds the step to a coordinate until it passes the end never ends when the
//! coordinate is so large that adding the step changes nothing (1e20 + 50 == 1e20); this one
//! runs at most `max` times whatever the values.

/// The multiples `k * step` in `[lo, hi]`, in increasing order, or none when there would be more
/// than `max` of them, when `step` is not positive or when a bound is not finite (a drawing
/// then has no grid rather than a wrong or endless one).
pub fn multiples(lo: f64, hi: f64, step: f64, max: usize) -> impl Iterator<Item = f64> {
    let ok = lo.is_finite() && hi.is_finite() && step.is_finite() && step > 0.0 && lo <= hi;
    let (first, last) = if ok { ((lo / step).ceil(), (hi / step).floor()) } else { (1.0, 0.0) };
    // Counted in f64 first: the count of a huge interval does not fit in an integer.
    let count = if first.is_finite() && last.is_finite() && last >= first { last - first + 1.0 } else { 0.0 };
    let count = if count <= max as f64 { count as usize } else { 0 };
    (0..count).map(move |i| (first + i as f64) * step)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multiples_inside_the_interval_and_nothing_for_huge_or_bad_values() {
        assert_eq!(multiples(-60.0, 120.0, 50.0, 100).collect::<Vec<_>>(), vec![-50.0, 0.0, 50.0, 100.0]);
        assert_eq!(multiples(0.0, 100.0, 50.0, 100).collect::<Vec<_>>(), vec![0.0, 50.0, 100.0]);
        // 1e20 + 50 == 1e20: an adding loop would never end; here 3 lines or none.
        assert_eq!(multiples(1e20, 1e20 + 100.0, 50.0, 100).count(), 1);
        assert_eq!(multiples(-1e300, 1e300, 50.0, 100).count(), 0);
        for (lo, hi, step) in
            [(f64::NAN, 1.0, 1.0), (0.0, f64::INFINITY, 1.0), (0.0, 1.0, 0.0), (0.0, 1.0, -1.0), (2.0, 1.0, 1.0)]
        {
            assert_eq!(multiples(lo, hi, step, 100).count(), 0, "{lo} {hi} {step}");
        }
    }
}
