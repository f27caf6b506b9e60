//! Height-field horizons: the exact reference against analytic answers and dense
//! sampling, and SN08's multi-resolution march against the exact reference.
//!
//! The error tables behind `HorizonSettings::default` come from
//! `measure_error_vs_settings`:
//!
//!     cargo test --release --test suite heightfield::measure -- --ignored --nocapture

use logsh::heightfield::{
    brute_force_horizon, HeightField, HeightFieldError, HorizonPyramid, HorizonSettings, LevelReconstruction, ScaleMax,
};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

// ---------------------------------------------------------------------------
// Tolerances

/// Exact reference against closed forms: the reference is exact up to f64 rounding
/// of a quadratic fit per cell, and the analytic scenes are exactly representable
/// by the bilinear surface, so only rounding remains.
const EXACT_TOL: f64 = 1e-9;
/// Exact reference against dense sampling (t step = spacing/128): sampling can only
/// fall short of the true maximum, by at most (slope change over a step) ~ 1e-4 rad
/// on these fields.
const DENSE_SAMPLING_TOL: f64 = 2e-3;
/// Dense sampling can exceed the exact value only through f64 rounding of the
/// sample position: one ulp of x (~6e-17) times a slope of ~2, divided by the
/// smallest t sampled (~2e-10), about 1e-6 rad.
const DENSE_ROUNDING_TOL: f64 = 1e-5;
/// A constant field through the pyramid: every level is the same constant (the tent
/// weights and B-spline weights sum to 1 up to f64 rounding), so the march sees
/// differences of ~1e-16 over distances >= one spacing.
const FLAT_TOL: f64 = 1e-9;
// The SN08 march is biased low by design: every level is prefiltered (a tent of one
// level spacing) and read through a bicubic B-spline, so peaks and crests read at a
// distance are lowered, and a horizon closer than the first step (half a spacing) is
// missed. The bounds below are the default settings' measured errors (printed by
// each test with --nocapture) with a margin of about 1.5x, so a regression shows.

/// Cone (65x65, unit height, slope 2), 60 points on the ground and the flanks, 16
/// azimuths: mean |error|. Measured 0.0061 rad, bias -0.0039.
const CONE_MEAN_TOL: f64 = 0.01;
/// Same, worst direction. Measured 0.136 rad, next to the apex, where the rounded
/// (filtered) apex is lowest relative to the sharp one. Also bounds the cast shadow
/// on a point 0.3 above the ground (measured 0.133: the apex read at distance 0.8
/// through a level of spacing 0.8/8 loses about a quarter of its height above p).
const CONE_MAX_TOL: f64 = 0.2;
/// Sine grating (amplitude 0.1, wavelength 1, 32 samples per wavelength), 40 points,
/// 12 azimuths every 30 degrees from the ridge normal: mean |error|. Measured 0.0091.
const GRATING_MEAN_TOL: f64 = 0.015;
/// Worst direction on the grating. Measured 0.080 rad: distant crests are flattened
/// by the coarser levels the march reads there.
const GRATING_MAX_TOL: f64 = 0.12;
/// 2x2 tilted plane (z = x on the unit square). The bicubic B-spline of only two
/// samples per axis, edge samples replicated, is not the ramp: mid-cell it is 1/2,
/// at the edge 5/6, so the first step (half a spacing) reads a tangent of 2/3:
/// atan(2/3) = 0.588 instead of pi/4 = 0.785, an error of 0.197.
const TINY_MAP_TOL: f64 = 0.22;
/// 1xN and Nx1 maps (a sine of amplitude 0.2, wavelength 1, along the one moving
/// axis), 30 points, 16 azimuths. Measured mean 0.0175 rad, max 0.151 (oblique
/// azimuths, where the crest is far and read from a coarse level).
const PROFILE_MEAN_TOL: f64 = 0.03;
const PROFILE_MAX_TOL: f64 = 0.2;
/// Rough terrain (129x129, RMS slope about 1) including points 0.1 above it and
/// points outside the map: mean |error|. Measured 0.037 rad.
const ROUGH_MEAN_TOL: f64 = 0.06;

// ---------------------------------------------------------------------------
// Helpers

/// Builds a field by sampling `f` at the corner-registered sample positions.
fn sampled(columns: usize, rows: usize, min: [f64; 2], max: [f64; 2], f: impl Fn(f64, f64) -> f64) -> HeightField {
    let mut heights = Vec::with_capacity(columns * rows);
    for j in 0..rows {
        for i in 0..columns {
            let x = if columns > 1 { min[0] + (max[0] - min[0]) * i as f64 / (columns - 1) as f64 } else { min[0] };
            let y = if rows > 1 { min[1] + (max[1] - min[1]) * j as f64 / (rows - 1) as f64 } else { min[1] };
            heights.push(f(x, y) as f32);
        }
    }
    HeightField::new(heights, columns, rows, min, max).expect("valid test field")
}

const CONE_HEIGHT: f64 = 1.0;
const CONE_RADIUS: f64 = 0.5;

/// A cone of unit height and radius 0.5 centred at the origin, on [-1, 1]^2, 65x65:
/// the apex is a sample.
fn cone_field() -> HeightField {
    sampled(65, 65, [-1.0, -1.0], [1.0, 1.0], |x, y| CONE_HEIGHT * (1.0 - x.hypot(y) / CONE_RADIUS).max(0.0))
}

const GRATING_AMPLITUDE: f64 = 0.1;

/// Ridges along y: h = A sin(2 pi x) on [0, 4]^2, 129x129 (32 samples per wavelength).
fn grating_field() -> HeightField {
    sampled(129, 129, [0.0, 0.0], [4.0, 4.0], |x, _| GRATING_AMPLITUDE * (TAU * x).sin())
}

/// Rough terrain: 4 octaves of 3 plane waves each with pseudo-random directions and
/// phases, amplitude halving per octave (so every octave has the same slope, RMS
/// slope about 1), highest frequency 12 cycles per unit: at least 5 samples per
/// wavelength on a 129^2 map over [-1, 1]^2.
fn rough_field(n: usize) -> HeightField {
    let mut rng = Lcg(7);
    let waves: Vec<(f64, f64, f64, f64)> = (0..4)
        .flat_map(|octave| {
            let freq = 1.5 * 2f64.powi(octave);
            let amp = 0.06 * 0.5f64.powi(octave);
            (0..3).map(|_| (freq, amp, rng.next() * TAU, rng.next() * TAU)).collect::<Vec<_>>()
        })
        .collect();
    sampled(n, n, [-1.0, -1.0], [1.0, 1.0], |x, y| {
        waves.iter().map(|&(f, a, dir, ph)| a * (TAU * f * (x * dir.cos() + y * dir.sin()) + ph).sin()).sum()
    })
}

/// Thin walls: a flat map with 8 straight walls one sample thick and 0.15 high, at
/// pseudo-random positions and angles. The hardest case for the pyramid: a wall is
/// thinner than every coarse level's spacing, so it is either prefiltered down
/// (bias) or stepped over (aliasing, when steps are sparser than texels).
fn walls_field(n: usize) -> HeightField {
    let mut heights = vec![0.0f32; n * n];
    let mut rng = Lcg(31);
    for _ in 0..8 {
        let (x0, y0) = (rng.next() * (n - 1) as f64, rng.next() * (n - 1) as f64);
        let angle = rng.next() * PI;
        let length = (0.2 + 0.3 * rng.next()) * n as f64;
        let samples = (length * 2.0) as usize;
        for s in 0..samples {
            let t = s as f64 * 0.5;
            let (x, y) = ((x0 + t * angle.cos()).round(), (y0 + t * angle.sin()).round());
            if x >= 0.0 && y >= 0.0 && (x as usize) < n && (y as usize) < n {
                heights[y as usize * n + x as usize] = 0.15;
            }
        }
    }
    HeightField::new(heights, n, n, [-1.0, -1.0], [1.0, 1.0]).unwrap()
}

/// Tiny deterministic generator (no test dependency needed).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Horizon by dense sampling of the level-0 surface: an independent check of the
/// exact reference (can only under-estimate). Besides the uniform steps it samples
/// `t = step 2^-m` down to 2e-6 of a step (further down, f64 rounding of
/// `p + t u` dominates), so that the `t -> 0+` limit (the local
/// slope, which can live on a sliver of a cell when the point sits next to a cell
/// edge) is seen too.
fn dense_sampled_horizon(field: &HeightField, p: [f64; 3], azimuth: f64, t_max: f64, step: f64) -> f64 {
    let (c, s) = (azimuth.cos(), azimuth.sin());
    let mut best: f64 = 0.0;
    for m in 1..20 {
        let t = step * 0.5f64.powi(m);
        best = best.max((field.height_at(p[0] + t * c, p[1] + t * s) - p[2]).atan2(t));
    }
    let mut t = step;
    while t <= t_max {
        best = best.max((field.height_at(p[0] + t * c, p[1] + t * s) - p[2]).atan2(t));
        t += step;
    }
    best
}

fn on_surface(field: &HeightField, x: f64, y: f64) -> [f64; 3] {
    [x, y, field.height_at(x, y)]
}

struct ErrorStats {
    mean: f64,
    max: f64,
    /// Mean signed error (march minus exact): the bias.
    bias: f64,
}

/// March vs exact at the pyramid's own W azimuths, for the given points.
fn march_error(field: &HeightField, pyramid: &HorizonPyramid, points: &[[f64; 3]]) -> ErrorStats {
    let w = pyramid.settings().directions;
    let mut out = vec![0.0; w];
    let (mut sum, mut max, mut signed, mut count) = (0.0, 0.0f64, 0.0, 0usize);
    for &p in points {
        pyramid.horizon_elevations(p, &mut out);
        for (k, &h) in out.iter().enumerate() {
            let exact = brute_force_horizon(field, p, TAU * k as f64 / w as f64);
            let e = h - exact;
            sum += e.abs();
            signed += e;
            max = max.max(e.abs());
            count += 1;
        }
    }
    ErrorStats { mean: sum / count as f64, max, bias: signed / count as f64 }
}

/// Error of the azimuthally interpolated horizon (paper 000 Eq. 19 / SN08 Eq. 6
/// interpolate linearly between the W samples) against the exact horizon at
/// `dense` azimuths: this is the error W controls.
fn interpolated_error(field: &HeightField, pyramid: &HorizonPyramid, points: &[[f64; 3]], dense: usize) -> ErrorStats {
    let w = pyramid.settings().directions;
    let mut out = vec![0.0; w];
    let (mut sum, mut max, mut signed, mut count) = (0.0, 0.0f64, 0.0, 0usize);
    for &p in points {
        pyramid.horizon_elevations(p, &mut out);
        for d in 0..dense {
            // Offset by half a dense step so the dense azimuths avoid the W samples.
            let phi = TAU * (d as f64 + 0.5) / dense as f64;
            let u = phi / TAU * w as f64;
            let k = u.floor() as usize % w;
            let a = u - u.floor();
            let interp = (1.0 - a) * out[k] + a * out[(k + 1) % w];
            let e = interp - brute_force_horizon(field, p, phi);
            sum += e.abs();
            signed += e;
            max = max.max(e.abs());
            count += 1;
        }
    }
    ErrorStats { mean: sum / count as f64, max, bias: signed / count as f64 }
}

fn random_surface_points(field: &HeightField, count: usize, seed: u64, lo: f64, hi: f64, lift: f64) -> Vec<[f64; 3]> {
    let mut rng = Lcg(seed);
    (0..count)
        .map(|_| {
            let x = lo + (hi - lo) * rng.next();
            let y = lo + (hi - lo) * rng.next();
            let p = on_surface(field, x, y);
            [p[0], p[1], p[2] + lift]
        })
        .collect()
}

// ---------------------------------------------------------------------------
// The exact reference

#[test]
fn reference_matches_cone_closed_form() {
    // From a ground point at distance D >= R from the axis, looking at the apex along
    // a grid row, the horizon is the apex: atan(H / D) (the flank's elevation
    // H(1 - (D - t)/R)/t increases up to t = D, and decreases beyond it).
    let field = cone_field();
    for &d in &[0.5, 0.625, 0.75, 0.9375] {
        for (k, azimuth) in [0.0, FRAC_PI_2, PI, 1.5 * PI].into_iter().enumerate() {
            let (x, y) = (-d * azimuth.cos(), -d * azimuth.sin());
            let p = on_surface(&field, x, y);
            let got = brute_force_horizon(&field, p, azimuth);
            let expected = (CONE_HEIGHT / d).atan();
            assert!((got - expected).abs() < EXACT_TOL, "D = {d}, azimuth #{k}: got {got}, expected {expected}");
        }
    }
    // Looking away from the cone over flat ground: 0.
    let p = on_surface(&field, 0.75, 0.0);
    assert!(brute_force_horizon(&field, p, 0.0).abs() < EXACT_TOL);
}

#[test]
fn reference_matches_dense_sampling() {
    for field in [cone_field(), rough_field(33)] {
        for p in random_surface_points(&field, 12, 3, -1.2, 1.2, 0.0) {
            for k in 0..12 {
                let azimuth = TAU * k as f64 / 12.0 + 0.1;
                let exact = brute_force_horizon(&field, p, azimuth);
                // Out to 25 units: beyond the map the clamped footprint can slide along
                // an edge for ~10 units at grazing azimuths (the flat continuation).
                let dense = dense_sampled_horizon(&field, p, azimuth, 25.0, field.spacing()[0] / 128.0);
                assert!(
                    exact >= dense - DENSE_ROUNDING_TOL,
                    "reference below a sample: {exact} < {dense} at {p:?}, {azimuth}"
                );
                assert!(
                    exact - dense < DENSE_SAMPLING_TOL,
                    "reference {exact} far above dense sampling {dense} at {p:?}, {azimuth}"
                );
            }
        }
    }
}

#[test]
fn reference_tiny_ramp_and_flat_continuation() {
    // 2x2 map: z = x on [0, 1]^2, flat beyond: at x < 0 the height is 0, at x > 1 it is 1.
    let field = HeightField::new(vec![0.0, 1.0, 0.0, 1.0], 2, 2, [0.0, 0.0], [1.0, 1.0]).unwrap();
    let p = [0.5, 0.5, 0.5];
    // Uphill: slope 1, then the plateau at 1 seen at atan(0.5 / 0.5): both pi/4.
    assert!((brute_force_horizon(&field, p, 0.0) - FRAC_PI_4).abs() < EXACT_TOL);
    assert!(brute_force_horizon(&field, p, PI).abs() < EXACT_TOL);
    // Along the ridge line the profile is flat.
    assert!(brute_force_horizon(&field, p, FRAC_PI_2).abs() < EXACT_TOL);
    // Outside the map, 2 units to the left at height 0: the plateau edge at x = 1
    // (3 away, 1 up) is the horizon: atan(1 / 3).
    let q = [-2.0, 0.5, 0.0];
    assert!((brute_force_horizon(&field, q, 0.0) - (1.0f64 / 3.0).atan()).abs() < EXACT_TOL);
    // A point below the surface is buried.
    assert_eq!(brute_force_horizon(&field, [0.5, 0.5, 0.25], PI), FRAC_PI_2);
}

// ---------------------------------------------------------------------------
// The SN08 march

#[test]
fn flat_field_has_zero_horizon() {
    let field = sampled(17, 9, [-3.0, 2.0], [5.0, 4.0], |_, _| 2.5);
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
    let mut out = [1.0; 16];
    for p in [[0.0, 3.0, 2.5], [-3.0, 2.0, 2.5], [40.0, -7.0, 2.5], [1.0, 3.0, 2.5 + 1e-7]] {
        pyramid.horizon_elevations(p, &mut out);
        for (k, &h) in out.iter().enumerate() {
            assert!(h.abs() < FLAT_TOL, "p = {p:?}, direction {k}: horizon {h}, expected 0");
            assert!(brute_force_horizon(&field, p, TAU * k as f64 / 16.0).abs() < FLAT_TOL);
        }
    }
}

#[test]
fn point_above_flat_field_has_zero_horizon() {
    let field = sampled(9, 9, [0.0, 0.0], [1.0, 1.0], |_, _| -1.0);
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
    let mut out = [1.0; 16];
    for p in [[0.5, 0.5, 0.0], [0.5, 0.5, 100.0], [3.0, -2.0, 0.5]] {
        pyramid.horizon_elevations(p, &mut out);
        assert!(out.iter().all(|h| h.abs() < FLAT_TOL), "p = {p:?}: {out:?}");
        for k in 0..16 {
            assert!(brute_force_horizon(&field, p, TAU * k as f64 / 16.0).abs() < FLAT_TOL);
        }
    }
}

#[test]
fn one_by_one_map_is_an_infinite_plane() {
    let field = HeightField::new(vec![3.0], 1, 1, [0.0, 0.0], [1.0, 1.0]).unwrap();
    assert_eq!(field.height_at(-100.0, 55.0), 3.0);
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
    assert_eq!(pyramid.max_steps(), 0, "a plane needs no marching");
    let mut out = [1.0; 16];
    pyramid.horizon_elevations([0.3, 7.0, 3.0], &mut out);
    assert!(out.iter().all(|&h| h == 0.0));
    assert_eq!(brute_force_horizon(&field, [0.3, 7.0, 3.0], 1.0), 0.0);
    assert_eq!(brute_force_horizon(&field, [0.3, 7.0, 5.0], 1.0), 0.0);
    assert_eq!(brute_force_horizon(&field, [0.3, 7.0, 2.0], 1.0), FRAC_PI_2);
}

#[test]
fn tiny_two_by_two_map() {
    let field = HeightField::new(vec![0.0, 1.0, 0.0, 1.0], 2, 2, [0.0, 0.0], [1.0, 1.0]).unwrap();
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
    assert_eq!(pyramid.levels().len(), 1);
    let mut out = [0.0; 16];
    let p = [0.5, 0.5, 0.5];
    pyramid.horizon_elevations(p, &mut out);
    for (k, &h) in out.iter().enumerate() {
        let exact = brute_force_horizon(&field, p, TAU * k as f64 / 16.0);
        println!("2x2 direction {k}: march {h:.4}, exact {exact:.4}");
        assert!((h - exact).abs() < TINY_MAP_TOL, "direction {k}: march {h}, exact {exact}");
    }
    // Uphill is pi/4 exactly; the march reads the B-spline ramp (module doc).
    assert!((out[0] - FRAC_PI_4).abs() < TINY_MAP_TOL, "uphill: {}", out[0]);
    assert!(out[8].abs() < FLAT_TOL, "downhill: {}", out[8]);
}

#[test]
fn one_row_and_one_column_maps() {
    // One column: constant across x, a sine along y; one row: the transpose.
    let column = sampled(1, 65, [0.0, 0.0], [1.0, 2.0], |_, y| 0.2 * (TAU * y).sin());
    let row = sampled(65, 1, [0.0, 0.0], [2.0, 1.0], |x, _| 0.2 * (TAU * x).sin());
    for (field, along) in [(column, FRAC_PI_2), (row, 0.0)] {
        let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
        let points = random_surface_points(&field, 30, 11, 0.1, 0.9, 0.0);
        let stats = march_error(&field, &pyramid, &points);
        println!("1xN / Nx1: mean |err| {:.4} rad, max {:.4} rad, bias {:+.4} rad", stats.mean, stats.max, stats.bias);
        assert!(stats.mean < PROFILE_MEAN_TOL, "mean error {} >= {}", stats.mean, PROFILE_MEAN_TOL);
        assert!(stats.max < PROFILE_MAX_TOL, "max error {} >= {}", stats.max, PROFILE_MAX_TOL);
        // Across the profile (perpendicular to `along`) the field is constant: 0.
        let p = points[0];
        assert!(brute_force_horizon(&field, p, along + FRAC_PI_2).abs() < EXACT_TOL);
    }
}

#[test]
fn cone_march_matches_reference() {
    let field = cone_field();
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
    // Ground around the cone, flanks, and the whole map (some points near the apex).
    let points = random_surface_points(&field, 60, 5, -1.0, 1.0, 0.0);
    let stats = march_error(&field, &pyramid, &points);
    println!("cone: mean |err| {:.4} rad, max {:.4} rad, bias {:+.4} rad", stats.mean, stats.max, stats.bias);
    assert!(stats.mean < CONE_MEAN_TOL, "cone mean error {} >= {}", stats.mean, CONE_MEAN_TOL);
    assert!(stats.max < CONE_MAX_TOL, "cone max error {} >= {}", stats.max, CONE_MAX_TOL);
}

#[test]
fn rough_terrain_march_matches_reference() {
    let field = rough_field(129);
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
    let mut points = random_surface_points(&field, 30, 41, -0.95, 0.95, 0.0);
    points.extend(random_surface_points(&field, 10, 42, -0.95, 0.95, 0.1));
    // Off the map (a blocker-sphere point beyond the terrain's edge).
    points.extend(random_surface_points(&field, 10, 43, 1.05, 1.6, 0.05));
    let stats = march_error(&field, &pyramid, &points);
    println!("rough: mean |err| {:.4} rad, max {:.4} rad, bias {:+.4} rad", stats.mean, stats.max, stats.bias);
    assert!(stats.mean < ROUGH_MEAN_TOL, "rough mean error {} >= {}", stats.mean, ROUGH_MEAN_TOL);
}

#[test]
fn cone_casts_on_point_above_ground() {
    // Cast shadow on a non-height-field point (paper 000 Section 4.1): a point 0.3
    // above the ground, 0.8 from the axis, looking at the cone.
    let field = cone_field();
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
    let p = [-0.8, 0.0, 0.3];
    let mut out = [0.0; 16];
    pyramid.horizon_elevations(p, &mut out);
    let exact = brute_force_horizon(&field, p, 0.0);
    assert!((exact - (0.7f64 / 0.8).atan()).abs() < EXACT_TOL);
    println!("cast: march {:.4}, exact {exact:.4}", out[0]);
    assert!((out[0] - exact).abs() < CONE_MAX_TOL, "march {} exact {exact}", out[0]);
    assert!(out[8].abs() < FLAT_TOL, "away from the cone: {}", out[8]);
}

#[test]
fn grating_march_matches_reference() {
    let field = grating_field();
    // Azimuths 0, 30, 60, 90, ... degrees relative to the ridge normal (+X).
    let settings = HorizonSettings { directions: 12, ..HorizonSettings::default() };
    let pyramid = HorizonPyramid::new(&field, settings).unwrap();
    let points = random_surface_points(&field, 40, 9, 0.5, 3.5, 0.0);
    let stats = march_error(&field, &pyramid, &points);
    println!("grating: mean |err| {:.4} rad, max {:.4} rad, bias {:+.4} rad", stats.mean, stats.max, stats.bias);
    assert!(stats.mean < GRATING_MEAN_TOL, "grating mean error {} >= {}", stats.mean, GRATING_MEAN_TOL);
    assert!(stats.max < GRATING_MAX_TOL, "grating max error {} >= {}", stats.max, GRATING_MAX_TOL);
    // Along the ridges (90 and 270 degrees) the profile is flat: exactly 0 both ways.
    let mut out = [0.0; 12];
    for &p in &points {
        pyramid.horizon_elevations(p, &mut out);
        assert!(out[3].abs() < FLAT_TOL && out[9].abs() < FLAT_TOL, "along ridges: {} {}", out[3], out[9]);
    }
}

#[test]
fn horizons_are_bounded_and_finite_everywhere() {
    let field = rough_field(33);
    for reconstruction in [LevelReconstruction::BicubicBSpline, LevelReconstruction::Bilinear] {
        for scale_max in [ScaleMax::BSpline, ScaleMax::Steps] {
            let settings = HorizonSettings { reconstruction, scale_max, ..HorizonSettings::default() };
            let pyramid = HorizonPyramid::new(&field, settings).unwrap();
            let mut out = [0.0; 16];
            let far = [
                [50.0, -30.0, 0.0],
                [1.0, 1.0, -10.0],
                [0.0, 0.0, 1e6],
                [f64::NAN, 0.0, 0.0],
                [f64::INFINITY, 1.0, 1.0],
            ];
            for p in random_surface_points(&field, 20, 1, -1.5, 1.5, 0.0).into_iter().chain(far) {
                pyramid.horizon_elevations(p, &mut out);
                assert!(out.iter().all(|h| h.is_finite() && *h >= 0.0 && *h < FRAC_PI_2), "p = {p:?}: {out:?}");
            }
        }
    }
}

#[test]
fn bad_inputs_are_typed_errors() {
    let ok = [0.0, 0.0];
    let one = [1.0, 1.0];
    assert!(matches!(HeightField::new(vec![], 0, 3, ok, one), Err(HeightFieldError::EmptyMap { .. })));
    assert!(matches!(
        HeightField::new(vec![0.0; 3], 2, 2, ok, one),
        Err(HeightFieldError::SizeMismatch { expected: 4, len: 3, .. })
    ));
    let nan = HeightField::new(vec![0.0, 1.0, f32::NAN, 0.0], 2, 2, ok, one).unwrap_err();
    assert!(matches!(nan, HeightFieldError::NonFiniteHeight { column: 0, row: 1, .. }), "{nan}");
    assert!(nan.to_string().contains("column 0, row 1"), "{nan}");
    assert!(matches!(
        HeightField::new(vec![0.0, f32::INFINITY], 2, 1, ok, one),
        Err(HeightFieldError::NonFiniteHeight { column: 1, row: 0, .. })
    ));
    assert!(matches!(HeightField::new(vec![0.0; 4], 2, 2, one, ok), Err(HeightFieldError::BadRectangle { .. })));
    assert!(matches!(HeightField::new(vec![0.0; 4], 2, 2, ok, [1.0, 0.0]), Err(HeightFieldError::BadRectangle { .. })));
    assert!(matches!(
        HeightField::new(vec![0.0; 4], 2, 2, [f64::NAN, 0.0], one),
        Err(HeightFieldError::BadRectangle { .. })
    ));
    let field = HeightField::new(vec![0.0; 4], 2, 2, ok, one).unwrap();
    for bad in [
        HorizonSettings { directions: 0, ..HorizonSettings::default() },
        HorizonSettings { level_step: 0.0, ..HorizonSettings::default() },
        HorizonSettings { level_step: f64::NAN, ..HorizonSettings::default() },
        HorizonSettings { level_offset: -1.0, ..HorizonSettings::default() },
        HorizonSettings { level_offset: f64::INFINITY, ..HorizonSettings::default() },
    ] {
        let err = HorizonPyramid::new(&field, bad).unwrap_err();
        assert!(matches!(err, HeightFieldError::BadSetting { .. }), "{bad:?}: {err}");
        assert!(err.to_string().contains("horizon setting"), "{err}");
    }
}

// ---------------------------------------------------------------------------
// Measurement behind `HorizonSettings::default`

/// One measurement scene: a field, query points, and the exact horizons at the
/// W = 16 azimuths (computed once, shared by every setting).
struct Scene {
    name: &'static str,
    field: HeightField,
    points: Vec<[f64; 3]>,
    exact: Vec<[f64; 16]>,
}

fn scene(name: &'static str, field: HeightField, points: Vec<[f64; 3]>) -> Scene {
    let exact = points
        .iter()
        .map(|&p| std::array::from_fn(|k| brute_force_horizon(&field, p, TAU * k as f64 / 16.0)))
        .collect();
    Scene { name, field, points, exact }
}

fn measurement_scenes() -> Vec<Scene> {
    let rough = rough_field(129);
    let mut rough_points = random_surface_points(&rough, 150, 21, -0.9, 0.9, 0.0);
    // Cast-shadow receivers: points 0.1 above the terrain (paper 000 Section 4.1).
    rough_points.extend(random_surface_points(&rough, 50, 22, -0.9, 0.9, 0.1));
    let cone = cone_field();
    let cone_points = random_surface_points(&cone, 100, 23, -0.95, 0.95, 0.0);
    let grating = grating_field();
    let grating_points = random_surface_points(&grating, 100, 24, 0.5, 3.5, 0.0);
    let walls = walls_field(129);
    let walls_points = random_surface_points(&walls, 150, 25, -0.9, 0.9, 0.0);
    vec![
        scene("rough 129^2", rough, rough_points),
        scene("cone 65^2", cone, cone_points),
        scene("grating 129^2", grating, grating_points),
        scene("walls 129^2", walls, walls_points),
    ]
}

/// Aliasing ("wobble") of the march as the receiver slides: 128 receivers on a line
/// 16 level-0 spacings long (at 20 degrees to the grid so every phase of the grid is
/// crossed), total variation of (march - exact) along the line per azimuth, in
/// milliradians per spacing. A smoothly biased estimate scores low; an estimate that
/// steps over texels (so thin features appear and vanish as the receiver moves, the
/// shadow artifacts of SN08 Figures 3 and 9) scores high.
fn wobble(scene: &Scene, settings: HorizonSettings) -> f64 {
    let settings = HorizonSettings { directions: 16, ..settings };
    let pyramid = HorizonPyramid::new(&scene.field, settings).unwrap();
    let spacing = scene.field.spacing()[0];
    let step = spacing / 8.0;
    let mut out = [0.0; 16];
    let mut total = 0.0;
    for start in scene.points.iter().take(4) {
        let mut previous: Option<[f64; 16]> = None;
        for i in 0..128 {
            let p = on_surface(&scene.field, start[0] + i as f64 * step * 0.94, start[1] + i as f64 * step * 0.34);
            pyramid.horizon_elevations(p, &mut out);
            let e: [f64; 16] =
                std::array::from_fn(|k| out[k] - brute_force_horizon(&scene.field, p, TAU * k as f64 / 16.0));
            if let Some(prev) = previous {
                total += (0..16).map(|k| (e[k] - prev[k]).abs()).sum::<f64>();
            }
            previous = Some(e);
        }
    }
    1e3 * total / (4.0 * 16.0 * 16.0)
}

/// Mean |err|, max |err|, bias, mean steps per direction, ns per direction.
fn measure(scene: &Scene, settings: HorizonSettings) -> (f64, f64, f64, f64, f64) {
    let settings = HorizonSettings { directions: 16, ..settings };
    let pyramid = HorizonPyramid::new(&scene.field, settings).unwrap();
    let mut out = [0.0; 16];
    let (mut sum, mut max, mut signed, mut steps) = (0.0, 0.0f64, 0.0, 0usize);
    let start = std::time::Instant::now();
    for (p, exact) in scene.points.iter().zip(&scene.exact) {
        pyramid.horizon_elevations(*p, &mut out);
        for k in 0..16 {
            let e = out[k] - exact[k];
            sum += e.abs();
            signed += e;
            max = max.max(e.abs());
        }
    }
    let ns = start.elapsed().as_nanos() as f64 / (scene.points.len() * 16) as f64;
    for p in &scene.points {
        for k in 0..16 {
            steps += pyramid.steps_taken(p[0], p[1], k);
        }
    }
    let n = (scene.points.len() * 16) as f64;
    (sum / n, max, signed / n, steps as f64 / n, ns)
}

#[test]
#[ignore = "measurement: prints the error tables behind HorizonSettings::default"]
fn measure_error_vs_settings() {
    let scenes = measurement_scenes();
    let d = HorizonSettings::default();
    let row = |label: String, s: HorizonSettings| {
        let mut line = format!("{label:<34}");
        for sc in &scenes {
            let (mean, max, bias, steps, ns) = measure(sc, s);
            let wob = wobble(sc, s);
            line += &format!(" | {mean:.4} {max:.3} {bias:+.4} {wob:5.2} {steps:5.1} {ns:5.0}");
        }
        println!("{line}");
    };
    let header = || {
        let mut h = format!("{:<34}", "setting");
        for sc in &scenes {
            h += &format!(" | {:<40}", sc.name);
        }
        println!("{h}");
        println!("{:<34}{}", "", " | mean   max   bias    wobbl steps ns/dir".repeat(scenes.len()));
    };
    println!("\nA. level step k x level offset o (first_step 1, bicubic, B-spline max); errors in radians");
    header();
    for k in [1.0, 2.0, 4.0, 8.0] {
        for o in [0.0, 1.0, 2.0, 3.0, 4.0] {
            row(format!("k={k} o={o}"), HorizonSettings { level_step: k, level_offset: o, ..d });
        }
    }
    println!("\nB. first step (k 4)");
    header();
    for o in [2.0, 3.0] {
        for f in [1.0, 0.5, 0.25, 0.125] {
            row(format!("o={o} first_step={f}"), HorizonSettings { level_offset: o, first_step: f, ..d });
        }
    }
    println!("\nC. reconstruction x scale max (k 4, o 2)");
    header();
    for r in [LevelReconstruction::BicubicBSpline, LevelReconstruction::Bilinear] {
        for m in [ScaleMax::BSpline, ScaleMax::Steps] {
            for o in [2.0, 3.0] {
                row(
                    format!("{r:?} {m:?} o={o}"),
                    HorizonSettings { reconstruction: r, scale_max: m, level_offset: o, ..d },
                );
            }
        }
    }
    println!("\nE. candidate presets (W 16)");
    header();
    let sn08 = HorizonSettings { level_offset: 2.0, first_step: 1.0, scale_max: ScaleMax::BSpline, ..d };
    row("SN08 typical: k4 o2 f1 bicubic spline".into(), sn08);
    row("default".into(), d);
    row(
        "fast: k2 o2 f1 bilinear steps".into(),
        HorizonSettings {
            level_step: 2.0,
            level_offset: 2.0,
            first_step: 1.0,
            reconstruction: LevelReconstruction::Bilinear,
            ..d
        },
    );
    row("k4 o3 f0.5 bilinear steps".into(), HorizonSettings { reconstruction: LevelReconstruction::Bilinear, ..d });
    row(
        "fine: k8 o4 f0.25 bicubic steps".into(),
        HorizonSettings { level_step: 8.0, level_offset: 4.0, first_step: 0.25, ..d },
    );

    println!("\nF. pyramid build time (default settings)");
    for n in [129usize, 513, 1025] {
        let field = rough_field(n);
        let start = std::time::Instant::now();
        let pyramid = HorizonPyramid::new(&field, d).unwrap();
        let samples: usize = pyramid.levels().iter().map(|l| l.heights.len()).sum();
        println!(
            "{n}^2: {} levels, {:.2}x the map's samples, {} steps max, built in {:.1} ms",
            pyramid.levels().len(),
            samples as f64 / (n * n) as f64,
            pyramid.max_steps(),
            start.elapsed().as_secs_f64() * 1e3
        );
    }

    println!("\nD. azimuth count W: horizon interpolated linearly between azimuths (paper 000 Eq. 19) vs exact at 256 azimuths");
    println!("   'exact-W' interpolates exact horizons (the W error alone); 'march-W' interpolates the default march");
    for sc in &scenes {
        let pts: Vec<[f64; 3]> = sc.points.iter().copied().take(40).collect();
        for w in [4, 8, 12, 16, 24, 32, 48, 64] {
            let pyramid = HorizonPyramid::new(&sc.field, HorizonSettings { directions: w, ..d }).unwrap();
            let march = interpolated_error(&sc.field, &pyramid, &pts, 256);
            let exact = exact_interpolated_error(&sc.field, &pts, w, 256);
            println!(
                "{:<14} W={w:<3} exact-W mean {:.4} max {:.3} | march-W mean {:.4} max {:.3} bias {:+.4}",
                sc.name, exact.mean, exact.max, march.mean, march.max, march.bias
            );
        }
    }
}

/// Like [`interpolated_error`] but interpolating exact horizons: the error W alone
/// causes.
fn exact_interpolated_error(field: &HeightField, points: &[[f64; 3]], w: usize, dense: usize) -> ErrorStats {
    let (mut sum, mut max, mut signed, mut count) = (0.0, 0.0f64, 0.0, 0usize);
    for &p in points {
        let samples: Vec<f64> = (0..w).map(|k| brute_force_horizon(field, p, TAU * k as f64 / w as f64)).collect();
        for d in 0..dense {
            let phi = TAU * (d as f64 + 0.5) / dense as f64;
            let u = phi / TAU * w as f64;
            let k = u.floor() as usize % w;
            let a = u - u.floor();
            let e = (1.0 - a) * samples[k] + a * samples[(k + 1) % w] - brute_force_horizon(field, p, phi);
            sum += e.abs();
            signed += e;
            max = max.max(e.abs());
            count += 1;
        }
    }
    ErrorStats { mean: sum / count as f64, max, bias: signed / count as f64 }
}

#[test]
fn pyramid_structure_follows_sn08() {
    // SN08 Section 4: N = ceil(k log2 n) + 1 levels, memory gamma(k) = 1/(1 - 2^(-2/k))
    // times the map. Our level sizes are rounded up to whole samples and stop at 2x2,
    // so N matches within one level and memory within 5 %.
    let n = 257;
    let field = sampled(n, n, [0.0, 0.0], [1.0, 1.0], |x, y| (x * y).sin());
    for k in [1.0, 2.0, 4.0] {
        let pyramid =
            HorizonPyramid::new(&field, HorizonSettings { level_step: k, ..HorizonSettings::default() }).unwrap();
        let levels = pyramid.levels();
        let expected_n = (k * (n as f64 - 1.0).log2()).ceil() as usize + 1;
        assert!(levels.len().abs_diff(expected_n) <= 1, "k = {k}: {} levels, SN08 says {expected_n}", levels.len());
        let memory = levels.iter().map(|l| l.heights.len()).sum::<usize>() as f64 / (n * n) as f64;
        let gamma = 1.0 / (1.0 - 2f64.powf(-2.0 / k));
        assert!((memory / gamma - 1.0).abs() < 0.05, "k = {k}: memory {memory:.3}x, gamma {gamma:.3}");
        // Each level is a corner-registered grid over the same rectangle.
        for l in levels {
            assert_eq!(l.heights.len(), l.columns * l.rows);
            assert!((l.spacing[0] * (l.columns - 1) as f64 - 1.0).abs() < 1e-12);
        }
        // Step distances grow by b = 2^(1/k); levels never get finer with distance.
        for w in pyramid.steps().windows(2) {
            assert!((w[1].distance / w[0].distance - 2f64.powf(1.0 / k)).abs() < 1e-12);
            assert!(w[1].level >= w[0].level);
        }
    }
    // Shared across rayon workers by reference.
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<HorizonPyramid>();
    assert_send_sync::<HeightField>();
}
