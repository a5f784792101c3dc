//! Blender's default F-curve interpolation, as the keys-only benchmark's Bezier baseline: the
//! curve Blender draws through an animator's keys on one channel when the keys are inserted
//! with its factory settings (Blender 3.4: interpolation `BEZIER`, handle type `AUTO_CLAMPED`,
//! the curve's auto smoothing `CONT_ACCEL`, extrapolation `CONSTANT`).
//!
//! Written from Blender's algorithm (`BKE_fcurve_handles_recalc_ex`, then
//! `BKE_nurb_handle_smooth_fcurve` in `blenkernel/intern/curve.cc`), in f64; Blender computes
//! in f32. `apps/bench/tests/blender_bezier.rs` checks it against Blender itself, headless.
//!
//! For keys `(x_i, y_i)` (frames, values), `dx_i = x_i - x_(i-1)`, `dy_i = y_i - y_(i-1)`:
//!
//! 1. Every handle is a third of its interval long in time: key `i`'s left handle at
//!    `x_i - dx_i / 3`, its right handle at `x_i + dx_(i+1) / 3`, so time is linear in the
//!    Bezier parameter and a segment is the cubic Bezier `y0, y0 + r_0, y1 - l_1, y1` in
//!    `s = (x - x0) / dx`.
//! 2. Keys whose handles are fixed ("locked"): the first and the last key (flat handles: the
//!    curve eases in and out) and every local extremum (`y_(i-1)` and `y_(i+1)` both on one side
//!    of `y_i`, or equal: flat handles, so the curve does not overshoot the key).
//! 3. Between two locked keys the right-handle heights `h_i` (left handle height `-h_i / l_i`,
//!    `l_i = dx_(i+1) / dx_i`, so the slope is continuous) solve the tridiagonal system of
//!    continuous acceleration, `l_i^2 h_(i-1) + 2 (l_i + 1) h_i + h_(i+1) / l_(i+1) =
//!    dy_i l_i^2 + dy_(i+1)`, with the locked keys' handle heights as boundary values.
//! 4. Clamping ("auto clamped"): each `h_i` stays between 0 and `dy_(i+1)` and between 0 and
//!    `dy_i l_i` (no handle passes the next key's value or points backwards); a handle that
//!    leaves its range is locked at the bound and the system solved again, and a locked handle
//!    that the equations pull back into its range is released (at most twice), as Blender does.
//! 5. Outside the keys the curve holds the first and the last value.

use glam::{DQuat, DVec3};
use zoo_motion::euler::EulerOrder;

/// One key of a curve with its handles (time, value).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Key {
    x: f64,
    y: f64,
    left: [f64; 2],
    right: [f64; 2],
    locked: bool,
}

/// A channel's F-curve: keys with Blender's automatic clamped handles, evaluated at any time.
#[derive(Clone, Debug, PartialEq)]
pub struct FCurve {
    keys: Vec<Key>,
}

impl FCurve {
    /// The curve through `points` (time, value), times strictly increasing, with the handles
    /// Blender computes for keys inserted with its default settings. `None` without a point or
    /// with times that do not strictly increase or are not finite.
    pub fn auto_clamped(points: &[(f64, f64)]) -> Option<FCurve> {
        if points.is_empty()
            || points.iter().any(|(x, y)| !x.is_finite() || !y.is_finite())
            || points.windows(2).any(|w| w[0].0 >= w[1].0)
        {
            return None;
        }
        let n = points.len();
        let mut keys: Vec<Key> = (0..n).map(|i| first_pass(points, i)).collect();
        // Locked keys bound the runs smoothed together; the ends are always locked.
        let mut start = 0;
        for j in 1..n {
            if keys[j].locked {
                smooth_run(&mut keys[start..=j]);
                start = j;
            }
        }
        Some(FCurve { keys })
    }

    /// The curve's value at time `x` (the first or last key's value outside the keys).
    pub fn eval(&self, x: f64) -> f64 {
        let (first, last) = (&self.keys[0], &self.keys[self.keys.len() - 1]);
        if x <= first.x {
            return first.y;
        }
        if x >= last.x {
            return last.y;
        }
        let i = self.keys.partition_point(|k| k.x <= x) - 1;
        let (a, b) = (&self.keys[i], &self.keys[i + 1]);
        if x == a.x {
            return a.y;
        }
        let (mut p1, mut p2) = (a.right, b.left);
        correct_segment([a.x, a.y], &mut p1, &mut p2, [b.x, b.y]);
        let s = solve_time(x, a.x, p1[0], p2[0], b.x);
        bezier(a.y, p1[1], p2[1], b.y, s)
    }
}

/// Handles of key `i` from its neighbours (a missing neighbour mirrors the other one), with
/// the clamping of automatic clamped handles; the ends and the extrema locked flat.
fn first_pass(points: &[(f64, f64)], i: usize) -> Key {
    let (x, y) = points[i];
    let n = points.len();
    let prev = (i > 0).then(|| points[i - 1]);
    let next = (i + 1 < n).then(|| points[i + 1]);
    let (pa, pb) = match (prev, next) {
        (Some(p), Some(q)) => (p, q),
        (None, Some(q)) => ((2.0 * x - q.0, 2.0 * y - q.1), q),
        (Some(p), None) => (p, (2.0 * x - p.0, 2.0 * y - p.1)),
        (None, None) => return Key { x, y, left: [x, y], right: [x, y], locked: true },
    };
    let (len_a, len_b) = (x - pa.0, pb.0 - x);
    let slope = (y - pa.1) / len_a + (pb.1 - y) / len_b;
    // Handles a third of their interval long; their height follows the mean slope.
    let mut left = [x - len_a / 3.0, y - slope * len_a / 6.0];
    let mut right = [x + len_b / 3.0, y + slope * len_b / 6.0];
    let mut locked = prev.is_none() || next.is_none();
    if let (Some(p), Some(q)) = (prev, next) {
        let (d1, d2) = (p.1 - y, q.1 - y);
        if (d1 <= 0.0 && d2 <= 0.0) || (d1 >= 0.0 && d2 >= 0.0) {
            locked = true;
        } else {
            let mut left_violates = false;
            let mut right_violates = false;
            if (d1 <= 0.0 && p.1 > left[1]) || (d1 > 0.0 && p.1 < left[1]) {
                left[1] = p.1;
                left_violates = true;
            }
            if (d1 <= 0.0 && q.1 < right[1]) || (d1 > 0.0 && q.1 > right[1]) {
                right[1] = q.1;
                right_violates = true;
            }
            // The other handle stays aligned with the clamped one.
            let (h1, h2) = (left[0] - x, x - right[0]);
            if left_violates {
                right[1] = y + (y - left[1]) / h1 * h2;
            } else if right_violates {
                left[1] = y + (y - right[1]) / h2 * h1;
            }
        }
    }
    if locked {
        left[1] = y;
        right[1] = y;
    }
    Key { x, y, left, right, locked }
}

/// Limits `[lo, hi]` of handle height `i` for an interval rising by `dy` (clamped handles).
fn clamp_range(lo: &mut [f64], hi: &mut [f64], i: usize, dy: f64) {
    if dy > 0.0 {
        hi[i] = hi[i].min(dy);
        lo[i] = 0.0;
    } else if dy < 0.0 {
        hi[i] = 0.0;
        lo[i] = lo[i].max(dy);
    } else {
        lo[i] = 0.0;
        hi[i] = 0.0;
    }
}

/// A fixed handle's effect on the equations when its time length is not a third of the
/// interval (scaled down first when it is longer than the interval allows).
fn handle_adjustment(h: &mut [f64; 2], dx: f64) -> f64 {
    let fac = dx / (h[0] + dx / 3.0);
    if fac < 1.0 {
        h[0] *= fac;
        h[1] *= fac;
    }
    1.0 - 3.0 * h[0] / dx
}

/// Continuous acceleration over `keys` (a run whose first and last keys are locked): solves
/// the right-handle heights of the free keys between them, with the clamping limits.
fn smooth_run(keys: &mut [Key]) {
    let count = keys.len();
    if count <= 2 {
        return;
    }
    let mut dx = vec![f64::NAN; count];
    let mut dy = vec![f64::NAN; count];
    for i in 1..count {
        dx[i] = keys[i].x - keys[i - 1].x;
        dy[i] = keys[i].y - keys[i - 1].y;
    }
    let mut l = vec![1.0; count];
    for i in 1..count - 1 {
        l[i] = dx[i + 1] / dx[i];
    }
    let (mut lo, mut hi) = (vec![f64::MIN; count], vec![f64::MAX; count]);
    for i in 1..count {
        clamp_range(&mut lo, &mut hi, i - 1, dy[i]);
        clamp_range(&mut lo, &mut hi, i, dy[i] * l[i]);
    }
    let mut sys = Tridiagonal::zeros(count);
    let mut first = [keys[0].right[0] - keys[0].x, keys[0].right[1] - keys[0].y];
    let first_adj = handle_adjustment(&mut first, dx[1]);
    sys.lock(0, first[1]);
    let last_key = &keys[count - 1];
    let mut last = [last_key.x - last_key.left[0], last_key.y - last_key.left[1]];
    let last_adj = handle_adjustment(&mut last, dx[count - 1]);
    sys.lock(count - 1, last[1]);
    for i in 1..count - 1 {
        sys.a[i] = l[i] * l[i];
        sys.b[i] = 2.0 * (l[i] + 1.0);
        sys.c[i] = 1.0 / l[i + 1];
        sys.d[i] = dy[i] * l[i] * l[i] + dy[i + 1];
    }
    sys.b[1] += l[1] * first_adj;
    sys.b[count - 2] += last_adj;
    let Some(h) = sys.solve_within(&lo, &hi) else { return };
    for i in 1..count - 1 {
        let k = &mut keys[i];
        k.left[1] = k.y - h[i] / l[i];
        k.right[1] = k.y + h[i];
    }
}

/// A tridiagonal system `a_i x_(i-1) + b_i x_i + c_i x_(i+1) = d_i`.
#[derive(Clone, Debug)]
struct Tridiagonal {
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    d: Vec<f64>,
}

impl Tridiagonal {
    fn zeros(n: usize) -> Self {
        Tridiagonal { a: vec![0.0; n], b: vec![0.0; n], c: vec![0.0; n], d: vec![0.0; n] }
    }

    /// Row `i` becomes `x_i = value`.
    fn lock(&mut self, i: usize, value: f64) {
        self.a[i] = 0.0;
        self.c[i] = 0.0;
        self.b[i] = 1.0;
        self.d[i] = value;
    }

    /// The Thomas algorithm; `None` on a zero pivot.
    fn solve(&self) -> Option<Vec<f64>> {
        let n = self.b.len();
        let (mut c1, mut d1) = (vec![0.0; n], vec![0.0; n]);
        for i in 0..n {
            let den = self.b[i] - if i > 0 { self.a[i] * c1[i - 1] } else { 0.0 };
            if den == 0.0 {
                return None;
            }
            c1[i] = self.c[i] / den;
            d1[i] = (self.d[i] - if i > 0 { self.a[i] * d1[i - 1] } else { 0.0 }) / den;
        }
        let mut x = d1;
        for i in (0..n - 1).rev() {
            x[i] -= c1[i] * x[i + 1];
        }
        Some(x)
    }

    /// Solves with every unknown kept within `[lo_i, hi_i]`: an unknown out of its range is
    /// locked at the nearer bound (preferably a non-zero bound) and the system solved again; a
    /// locked unknown whose equation pulls it back inside is released, at most twice each.
    fn solve_within(&self, lo: &[f64], hi: &[f64]) -> Option<Vec<f64>> {
        let n = self.b.len();
        let mut sys = self.clone();
        let mut locked = vec![false; n];
        let mut unlocks = vec![0u8; n];
        loop {
            let h = sys.solve()?;
            let (mut overshoot, mut any_locked, mut all) = (false, false, false);
            loop {
                for i in 0..n {
                    if h[i] >= lo[i] && h[i] <= hi[i] {
                        continue;
                    }
                    overshoot = true;
                    let target = if h[i] > hi[i] { hi[i] } else { lo[i] };
                    if target != 0.0 || all {
                        locked[i] = true;
                        sys.lock(i, target);
                        any_locked = true;
                    }
                }
                all = true;
                if !overshoot || any_locked {
                    break;
                }
            }
            let mut unlocked = false;
            if !any_locked {
                for i in 0..n {
                    if !locked[i] || unlocks[i] >= 2 {
                        continue;
                    }
                    let prev = if i > 0 { h[i - 1] } else { h[n - 1] };
                    let next = if i + 1 < n { h[i + 1] } else { h[0] };
                    let state = self.a[i] * prev + self.b[i] * h[i] + self.c[i] * next - self.d[i];
                    let relax = -state * self.b[i];
                    if (relax > 0.0 && h[i] < hi[i]) || (relax < 0.0 && h[i] > lo[i]) {
                        sys.a[i] = self.a[i];
                        sys.b[i] = self.b[i];
                        sys.c[i] = self.c[i];
                        sys.d[i] = self.d[i];
                        locked[i] = false;
                        unlocks[i] += 1;
                        unlocked = true;
                    }
                }
            }
            if !overshoot && !unlocked {
                return Some(h);
            }
        }
    }
}

/// Keeps a segment's handles within its time span (Blender's `BKE_fcurve_correct_bezpart`).
fn correct_segment(v1: [f64; 2], v2: &mut [f64; 2], v3: &mut [f64; 2], v4: [f64; 2]) {
    let h1 = [v1[0] - v2[0], v1[1] - v2[1]];
    let h2 = [v4[0] - v3[0], v4[1] - v3[1]];
    let len = v4[0] - v1[0];
    let (len1, len2) = (h1[0].abs(), h2[0].abs());
    if len1 + len2 == 0.0 {
        return;
    }
    if len1 > len {
        let f = len / len1;
        *v2 = [v1[0] - f * h1[0], v1[1] - f * h1[1]];
    }
    if len2 > len {
        let f = len / len2;
        *v3 = [v4[0] - f * h2[0], v4[1] - f * h2[1]];
    }
}

/// The cubic Bezier `q0..q3` at parameter `s`.
fn bezier(q0: f64, q1: f64, q2: f64, q3: f64, s: f64) -> f64 {
    let u = 1.0 - s;
    u * u * u * q0 + 3.0 * u * u * s * q1 + 3.0 * u * s * s * q2 + s * s * s * q3
}

/// The parameter at which the segment's time `x(s)` (monotonic after [`correct_segment`])
/// equals `x`. Handles a third of the segment long in time (automatic handles, every curve of
/// the keys' in-betweening) make `x(s)` linear, `x0 + s (x3 - x0)`, solved directly; other
/// handles by bisection to full f64 precision, which stops once the interval's midpoint is one
/// of its ends (the result of more halvings).
fn solve_time(x: f64, x0: f64, x1: f64, x2: f64, x3: f64) -> f64 {
    let len = x3 - x0;
    let third = |h: f64, at: f64| (h - at).abs() <= 1e-12 * len.abs();
    if len > 0.0 && third(x1, x0 + len / 3.0) && third(x2, x3 - len / 3.0) {
        return ((x - x0) / len).clamp(0.0, 1.0);
    }
    let (mut a, mut b) = (0.0f64, 1.0f64);
    for _ in 0..80 {
        let m = 0.5 * (a + b);
        if m == a || m == b {
            break;
        }
        if bezier(x0, x1, x2, x3, m) < x {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// Euler angles (degrees) of `q` in `order`, the representation nearest `prev`: each angle
/// moved by whole turns, and of the two triples giving the same rotation the closer one (as
/// Blender's BVH importer keeps a joint's curves continuous).
pub fn euler_near(order: EulerOrder, q: DQuat, prev: Option<[f64; 3]>) -> [f64; 3] {
    let e = order.from_quat_deg(q);
    let Some(p) = prev else { return e };
    let unwrap = |v: [f64; 3]| -> [f64; 3] {
        let mut o = v;
        for i in 0..3 {
            o[i] = v[i] + 360.0 * ((p[i] - v[i]) / 360.0).round();
        }
        o
    };
    let a = unwrap(e);
    let b = unwrap([e[0] + 180.0, 180.0 - e[1], e[2] + 180.0]);
    let dist = |v: &[f64; 3]| (0..3).map(|i| (v[i] - p[i]).abs()).sum::<f64>();
    if dist(&b) < dist(&a) { b } else { a }
}

/// Keys of a shot for [`bezier_inbetween`]: frames from 0, strictly increasing; per key the
/// root position and the local rotations (keys x joints); per key which groups it fixes
/// (group 0 the root position, `1 + j` joint `j`'s rotation; empty: every key whole).
#[derive(Clone, Copy, Debug)]
pub struct ShotKeys<'a> {
    /// Key frames.
    pub frames: &'a [usize],
    /// Root position per key.
    pub root: &'a [DVec3],
    /// Local rotations, keys x joints.
    pub rot: &'a [DQuat],
    /// Per key, `1 + joints` flags; empty: whole keys.
    pub fixed: &'a [Vec<bool>],
}

impl ShotKeys<'_> {
    fn fixes(&self, k: usize, g: usize) -> bool {
        self.fixed.get(k).is_none_or(|m| m[g])
    }
}

/// Blender's default F-curves ([`FCurve::auto_clamped`]) through the root position channels
/// and each joint's Euler channels (degrees, in `orders[j]`, continuous along the keys by
/// [`euler_near`]) at the keys that fix them, evaluated at frames `0..=last key`: root
/// positions and local rotations (frames x joints), each joint's rotation signs continuous
/// from its first key's. `None` when a group is fixed by no key, or the frames do not strictly
/// increase.
pub fn bezier_inbetween(orders: &[EulerOrder], keys: &ShotKeys<'_>) -> Option<(Vec<DVec3>, Vec<DQuat>)> {
    let j = orders.len();
    let n = keys.frames.last()? + 1;
    if keys.root.len() != keys.frames.len() || keys.rot.len() != keys.frames.len() * j {
        return None;
    }
    let fixing = |g: usize| (0..keys.frames.len()).filter(move |&k| keys.fixes(k, g));
    let mut root = vec![DVec3::ZERO; n];
    for c in 0..3 {
        let pts: Vec<(f64, f64)> = fixing(0).map(|k| (keys.frames[k] as f64, keys.root[k][c])).collect();
        let fc = FCurve::auto_clamped(&pts)?;
        for (f, r) in root.iter_mut().enumerate() {
            r[c] = fc.eval(f as f64);
        }
    }
    let mut rot = vec![DQuat::IDENTITY; n * j];
    for (jj, &order) in orders.iter().enumerate() {
        let mut prev: Option<[f64; 3]> = None;
        let pts: Vec<(f64, [f64; 3])> = fixing(1 + jj)
            .map(|k| {
                let e = euler_near(order, keys.rot[k * j + jj], prev);
                prev = Some(e);
                (keys.frames[k] as f64, e)
            })
            .collect();
        let first = fixing(1 + jj).next()?;
        let curves: Vec<FCurve> = (0..3)
            .map(|c| FCurve::auto_clamped(&pts.iter().map(|(f, e)| (*f, e[c])).collect::<Vec<_>>()))
            .collect::<Option<_>>()?;
        let mut last = keys.rot[first * j + jj];
        for f in 0..n {
            let q = order.to_quat_deg([0, 1, 2].map(|c| curves[c].eval(f as f64)));
            last = if q.dot(last) < 0.0 { -q } else { q };
            rot[f * j + jj] = last;
        }
    }
    Some((root, rot))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blender 3.4.1 (`blender -b --factory-startup`), four keys inserted with
    /// `fcurve.keyframe_points.insert` and `fcurve.evaluate` at frames 0, 3, ..., 30: every
    /// interior key is an extremum here, so every handle is flat.
    #[test]
    #[allow(clippy::approx_constant)] // 3.14 is a value Blender evaluated, not pi.
    fn matches_blender_on_extrema() {
        let c = FCurve::auto_clamped(&[(0.0, 0.0), (10.0, 5.0), (20.0, 3.0), (30.0, 8.0)]).unwrap();
        let blender = [0.0, 1.08, 3.24, 4.860001, 4.792, 4.0, 3.208, 3.14, 4.76, 6.920001, 8.0];
        for (i, want) in blender.iter().enumerate() {
            let got = c.eval(3.0 * i as f64);
            assert!((got - want).abs() < 1e-5, "frame {}: {got} vs Blender {want}", 3 * i);
        }
    }

    #[test]
    fn hits_keys_holds_outside_and_stays_within_monotonic_keys() {
        let pts = [(0.0, 0.0), (5.0, 1.0), (10.0, 4.0), (15.0, 4.5), (30.0, 10.0)];
        let c = FCurve::auto_clamped(&pts).unwrap();
        for (x, y) in pts {
            assert_eq!(c.eval(x), y);
        }
        assert_eq!(c.eval(-3.0), 0.0);
        assert_eq!(c.eval(40.0), 10.0);
        // Rising keys: clamped handles never overshoot, the curve rises monotonically.
        let mut prev = f64::MIN;
        for f in 0..=300 {
            let v = c.eval(f as f64 * 0.1);
            assert!(v >= prev - 1e-12 && (0.0..=10.0).contains(&v), "frame {}: {v}", f as f64 * 0.1);
            prev = v;
        }
    }

    /// The segment's parameter by 80 halvings, as it was solved before the direct solution.
    fn bisect(x: f64, q: [f64; 4]) -> f64 {
        let (mut a, mut b) = (0.0f64, 1.0f64);
        for _ in 0..80 {
            let m = 0.5 * (a + b);
            if bezier(q[0], q[1], q[2], q[3], m) < x {
                a = m;
            } else {
                b = m;
            }
        }
        0.5 * (a + b)
    }

    #[test]
    fn segment_times_solve_as_by_eighty_halvings() {
        let mut rng = zoo_motion::rng::SplitMix64::new(3);
        for _ in 0..2000 {
            let x0 = 60.0 * rng.next_f64() - 10.0;
            let len = 0.5 + 40.0 * rng.next_f64();
            let x = x0 + len * rng.next_f64();
            // Automatic handles (a third of the segment): the direct solution, within rounding.
            let thirds = [x0, x0 + len / 3.0, x0 + len - len / 3.0, x0 + len];
            let (got, want) = (solve_time(x, thirds[0], thirds[1], thirds[2], thirds[3]), bisect(x, thirds));
            assert!((got - want).abs() <= 1e-13, "{got} vs {want} at {x} in {thirds:?}");
            // Other handles: the same bisection, stopped once nothing changes.
            let other = [x0, x0 + 0.6 * len * rng.next_f64(), x0 + len * (0.4 + 0.6 * rng.next_f64()), x0 + len];
            assert_eq!(solve_time(x, other[0], other[1], other[2], other[3]), bisect(x, other), "{other:?} at {x}");
        }
    }

    #[test]
    fn refuses_unordered_or_missing_keys() {
        assert!(FCurve::auto_clamped(&[]).is_none());
        assert!(FCurve::auto_clamped(&[(1.0, 0.0), (1.0, 2.0)]).is_none());
        assert!(FCurve::auto_clamped(&[(0.0, f64::NAN), (1.0, 2.0)]).is_none());
        assert_eq!(FCurve::auto_clamped(&[(2.0, 7.0)]).unwrap().eval(5.0), 7.0);
    }
}
