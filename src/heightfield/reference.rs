//! Exact horizon of the level-0 (bilinear) surface, by walking every grid cell the
//! ray's footprint crosses.
//!
//! Along a ray `p + t (cos phi, sin phi)` the bilinear surface is a quadratic in `t`
//! inside each cell (both interpolation fractions are linear in `t`), and stays
//! quadratic (in fact linear) in the clamped region beyond the rectangle, because
//! there the height no longer depends on the clamped coordinate. Grid lines
//! (including the rectangle's edges) split the ray into such pieces. On a piece with
//! `H(t) - z = A t^2 + B t + C` the tangent of the elevation is `g(t) = A t + B + C/t`,
//! whose only interior stationary point is `t* = sqrt(C/A)` (when `C/A > 0`). The
//! maximum of `g` over the ray is therefore the maximum over piece ends and such
//! `t*`: this is SN08 Eq. 1 (paper 000 Eq. 10 maximised over `p'`) evaluated exactly,
//! up to f64 rounding, with no step size to choose.
//!
//! Beyond `t_far`, where both clamped coordinates stop moving, the height is a
//! constant `c`, so `atan((c - z)/t)` is monotone: its supremum is either its value
//! at `t_far` (a piece end) or the limit 0. Hence the result is exact out to and
//! including the infinite flat continuation.

use super::HeightField;
use std::f64::consts::FRAC_PI_2;

/// Exact horizon elevation (radians, in `[0, pi/2]`) of the level-0 surface seen
/// from the world point `p` along azimuth `azimuth` (from +X towards +Y).
///
/// `p` may lie on the surface (then the limit `t -> 0+`, the surface's directional
/// slope, counts, matching SN08 Eq. 1) or above it. A point more than a rounding
/// tolerance below the surface is buried: the answer is `pi/2` (every direction of
/// this azimuth is blocked). Cost: one quadratic fit per grid cell crossed, about
/// `columns + rows` cells for a ray across the map; it allocates nothing.
pub fn brute_force_horizon(field: &HeightField, p: [f64; 3], azimuth: f64) -> f64 {
    horizon_up_to(field, p, azimuth, FRAC_PI_2, f64::INFINITY)
}

/// Whether the exact horizon of [`brute_force_horizon`] reaches `elevation` (radians):
/// the direction `(azimuth, elevation)` from `p` is then blocked. The same walk, stopped
/// as soon as the answer is known: when the surface reaches the elevation, or when the
/// ray at that elevation has climbed above the highest sample (nothing further can reach
/// it). An upward direction from low terrain costs a few cells instead of the map.
pub fn horizon_reaches(field: &HeightField, p: [f64; 3], azimuth: f64, elevation: f64) -> bool {
    horizon_up_to(field, p, azimuth, elevation, f64::INFINITY) >= elevation
}

/// [`horizon_reaches`] for a light `reach` away horizontally (a point lamp): only the
/// surface nearer than that can block the direction.
pub fn horizon_reaches_within(field: &HeightField, p: [f64; 3], azimuth: f64, elevation: f64, reach: f64) -> bool {
    horizon_up_to(field, p, azimuth, elevation, reach) >= elevation
}

/// The exact horizon, of the surface no farther than `reach`, while it is below `stop`;
/// once it reaches `stop`, or once nothing further along the ray can, some value `>=
/// stop` or the (exact) horizon so far.
fn horizon_up_to(field: &HeightField, p: [f64; 3], azimuth: f64, stop: f64, reach: f64) -> f64 {
    let z = p[2];
    // The slope of a ray at the elevation `stop`, when it climbs.
    let climb = (stop > 0.0 && stop < FRAC_PI_2).then(|| stop.tan());
    let dir = [azimuth.cos(), azimuth.sin()];
    let at = |t: f64| field.height_at(p[0] + t * dir[0], p[1] + t * dir[1]);

    // A point is "on" the surface when it is within rounding of the f32 samples:
    // 1e-6 of the point's height scale (f32 carries ~6e-8 relative precision, and
    // G-buffer positions are f32 too).
    let surface_eps = 1e-6 * (1.0 + z.abs());
    let c0 = at(0.0) - z;
    if c0 > surface_eps {
        return FRAC_PI_2;
    }
    let on_surface = c0 >= -surface_eps;

    let n = [field.columns(), field.rows()];
    let (min, max) = (field.min(), field.max());

    // t_far: beyond it neither clamped coordinate moves, so the height is constant.
    let mut t_far: f64 = 0.0;
    for a in 0..2 {
        if n[a] > 1 {
            t_far = t_far.max(axis_exit(p[a], dir[a], min[a], max[a]));
        }
    }
    // The surface beyond `reach` counts for nothing: the walk ends there. Unbounded, the
    // flat continuation's horizon tends to the horizontal (the horizon is at least 0);
    // within a finite reach it may lie below it (`lowest_horizon`), and a continuation
    // below the receiver rises towards it until the reach.
    let mut best = super::pyramid::lowest_horizon(reach).atan();
    if reach.is_finite() && reach > t_far {
        best = best.max((at(t_far) - z).atan2(reach));
    }
    let t_far = t_far.min(reach);

    let mut crossings = [
        LineCrossings::new(p[0], dir[0], min[0], max[0], n[0], t_far),
        LineCrossings::new(p[1], dir[1], min[1], max[1], n[1], t_far),
    ];

    let mut t0 = 0.0;
    let mut y0 = c0 + z;
    while t0 < t_far {
        if best >= stop || climb.is_some_and(|k| z + t0 * k > field.highest()) {
            return best;
        }
        let t1 = crossings[0].peek().min(crossings[1].peek()).min(t_far);
        for c in crossings.iter_mut() {
            c.advance_past(t1);
        }
        if t1 <= t0 {
            continue;
        }
        if t1 - t0 <= 1e-9 * t1 {
            // Two grid lines crossed at the same point up to rounding: a fit through
            // three points this close is all rounding (it once gave a horizon of 0.756
            // where the surface reaches 0.608); only the end counts.
            let y1 = at(t1);
            best = best.max((y1 - z).atan2(t1));
            t0 = t1;
            y0 = y1;
            continue;
        }
        let tm = 0.5 * (t0 + t1);
        let ym = at(tm);
        let y1 = at(t1);
        // Quadratic through the three points, written about tm (Lagrange), then in t.
        let half = 0.5 * (t1 - t0);
        let a2 = (y0 - 2.0 * ym + y1) / (2.0 * half * half);
        let b_local = (y1 - y0) / (2.0 * half);
        let b = b_local - 2.0 * a2 * tm;
        let c = a2 * tm * tm - b_local * tm + ym - z;
        best = best.max((y1 - z).atan2(t1));
        if t0 == 0.0 && on_surface {
            // Limit t -> 0+ of g(t) for a point on the surface: the directional slope.
            best = best.max(b.atan());
        }
        if a2 != 0.0 && c / a2 > 0.0 {
            let t_star = (c / a2).sqrt();
            if t_star > t0 && t_star < t1 {
                best = best.max((a2 * t_star * t_star + b * t_star + c).atan2(t_star));
            }
        }
        t0 = t1;
        y0 = y1;
    }
    best.min(FRAC_PI_2)
}

/// Ray parameter at which coordinate `p + t d` has passed the far side of
/// `[min, max]` (0 if it never moves or already has).
fn axis_exit(p: f64, d: f64, min: f64, max: f64) -> f64 {
    if d > 0.0 {
        ((max - p) / d).max(0.0)
    } else if d < 0.0 {
        ((min - p) / d).max(0.0)
    } else {
        0.0
    }
}

/// The ray parameters, in increasing order, at which one coordinate crosses the grid
/// lines `min + i (max - min)/(n - 1)`, restricted to `(0, t_far]`.
struct LineCrossings {
    p: f64,
    d: f64,
    min: f64,
    spacing: f64,
    /// Next line index, as a signed float (decreasing when d < 0).
    next: f64,
    step: f64,
    remaining: usize,
}

impl LineCrossings {
    fn new(p: f64, d: f64, min: f64, max: f64, n: usize, t_far: f64) -> Self {
        let none = Self { p, d, min, spacing: 1.0, next: 0.0, step: 0.0, remaining: 0 };
        if n <= 1 || d == 0.0 || t_far <= 0.0 {
            return none;
        }
        let spacing = (max - min) / (n - 1) as f64;
        let u = (p - min) / spacing;
        let last = (n - 1) as f64;
        let (next, step, remaining) = if d > 0.0 {
            let first = (u.floor() + 1.0).max(0.0);
            (first, 1.0, if first > last { 0 } else { (last - first) as usize + 1 })
        } else {
            let first = (u.ceil() - 1.0).min(last);
            (first, -1.0, if first < 0.0 { 0 } else { first as usize + 1 })
        };
        Self { p, d, min, spacing, next, step, remaining }
    }

    fn peek(&self) -> f64 {
        if self.remaining == 0 {
            f64::INFINITY
        } else {
            (self.min + self.next * self.spacing - self.p) / self.d
        }
    }

    /// Drops every crossing at or before `t`.
    fn advance_past(&mut self, t: f64) {
        while self.remaining > 0 && self.peek() <= t {
            self.next += self.step;
            self.remaining -= 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The early-stopping test against the full walk, over points on and above a bumpy
    /// field and directions up, down and level with the horizon.
    #[test]
    fn horizon_reaches_agrees_with_the_full_walk() {
        let (columns, rows) = (23, 17);
        let heights: Vec<f32> = (0..columns * rows)
            .map(|i| {
                let (x, y) = ((i % columns) as f32, (i / columns) as f32);
                (0.7 * x).sin() * (0.4 * y).cos() + 0.05 * x
            })
            .collect();
        let field = HeightField::new(heights, columns, rows, [-3.0, -2.0], [4.0, 3.0]).unwrap();
        let mut checked = 0;
        for (x, y, lift) in [(0.1, 0.2, 0.0), (-2.5, 1.0, 0.0), (3.0, -1.5, 0.3), (0.7, 2.9, 2.0), (6.0, 0.0, 0.1)] {
            let p = [x, y, field.height_at(x, y) + lift];
            for k in 0..24 {
                let azimuth = std::f64::consts::TAU * k as f64 / 24.0;
                let horizon = brute_force_horizon(&field, p, azimuth);
                for elevation in [-0.3, 0.0, 0.05, 0.2, 0.5, 1.2, horizon - 1e-9, horizon + 1e-9] {
                    assert_eq!(
                        horizon_reaches(&field, p, azimuth, elevation),
                        horizon >= elevation,
                        "p {p:?}, azimuth {azimuth}, elevation {elevation}, horizon {horizon}"
                    );
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 5 * 24 * 8);
    }
}
