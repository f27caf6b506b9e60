//! Numerical extremes (issue item 5): eps from 1e-6 to 0.9, orders 3 and 8, every
//! exponentiation, 1 to 5000 overlapping blockers, receivers inside, touching and just
//! outside a blocker, blockers behind the surface, grazing normals, Phong exponents 1 to
//! 1024, vertical cliffs, flat and 1x1 height fields, NaN / Inf in the G-buffer, and
//! bounce light in a white furnace, off black surfaces and under suns of 1e6 and on or
//! below the horizon.
//!
//! Every shaded value must be finite and `>= 0`, alpha 1 on surfaces and 0 on the
//! background, below a stated bound, and the f32 kernel must agree with the f64 kernel
//! within a stated tolerance. `cargo test --test suite extremes:: -- --nocapture` prints the
//! measured worst values next to each bound.
use crate::support;

use logsh::executor::Executor;
use logsh::scene::{Frame, GBuffer, HeightMap, Material, Scene, SceneError, Sphere, SunLight};
use logsh::sh::ExpMethod;
use logsh::shade::bounce::BounceSettings;
use logsh::shade::{Quality, ShadedFrame, ShadedPasses, ShadingSettings};
use logsh::synth::{self, GBufferLayout, SphereOverPlane};
use std::path::Path;
use std::sync::Arc;
use support::TestRng;

const EPSILONS: [f64; 5] = [1e-6, 1e-3, 0.05, 0.5, 0.9];
const CHEAP_METHODS: [ExpMethod; 4] = [ExpMethod::Quad, ExpMethod::Ol, ExpMethod::Hyb, ExpMethod::Series];

/// Most an albedo-<=1 diffuse receiver under constant light 1 may come out as with
/// `quad` or `exact`. The true value is at most 1, but the log lobe is clamped at eps
/// times its peak, so at eps 0.9 the diffuse lobe is nearly isotropic (between 0.9/pi
/// and 1/pi everywhere) and the result approaches 4. Both methods clamp every node at
/// the lobe's log peak (`ExactExp::exp_below`), so the result is at most
/// `4 pi * peak * light = 4 pi / pi = 4`: a rigorous bound, not a fitted one.
/// Measured worst: 3.43 (no blockers, grazing normals, order 8, eps 0.9); 1.74 with 5000
/// blockers.
const MAX_DIFFUSE: f64 = 4.0;

/// The same ceiling for a Phong lobe of exponent r (albedo 0, specular 1): `4 pi (r + 1)
/// / (2 pi) = 2 (r + 1)`, 2050 at r = 1024. Measured worst 1752.6 (r = 1024, no
/// blockers, order 8, eps 0.9, where the clamp floor makes the lobe nearly isotropic).
const MAX_PHONG: f64 = 2050.0;

/// Largest |f32 - f64| of any channel of diffuse cases (values O(1)); measured worst
/// 1.9e-4 (5000 blockers, order 8, eps 1e-6). Sums of up to 5000 cap vectors of
/// magnitude up to `|log 1e-6| * 2 sqrt(pi)` per coefficient keep f32's relative
/// rounding; 5x headroom.
const PRECISION_TOLERANCE: f64 = 1e-3;

/// |f32 - f64| bound for the Phong cases, whose values reach ~1750 at r = 1024: measured
/// 6.0e-3 (3.4e-6 relative).
const PHONG_PRECISION_TOLERANCE: f64 = 2e-2;

// ---- scenes ------------------------------------------------------------------------

/// The sphere-over-plane scene (plane albedo 1, a geometry sphere of albedo 0.8 at
/// (0, 0, 2), constant white light, camera above) written and loaded; the frame's
/// blockers are replaced by each test.
fn base_scene(dir: &Path, width: u32, height: u32) -> (Scene, Frame) {
    let spec = SphereOverPlane { width, height, ..SphereOverPlane::default() };
    synth::sphere_over_plane(dir, &spec).expect("write scene");
    let scene = Scene::load(dir).expect("load scene");
    let frame = scene.frame(1).expect("load frame");
    (scene, frame)
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

fn add(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn surface_pixels(g: &GBuffer) -> Vec<usize> {
    (0..g.material.len()).filter(|&i| g.material[i] != 0).collect()
}

/// `count` blockers clustered on the receivers: the first is a large sphere around the
/// origin that contains the geometry sphere and many plane pixels; the rest are placed
/// relative to a random receiver `p` with normal `n` and radius `r`, cycling through:
/// touching (`c = p + r n`), just outside (`r (1 + 1e-6)`), containing `p` in front,
/// wholly behind the tangent plane, containing `p` with the centre behind, centred on
/// `p`, and two random placements within `1.5 r` of `p` (about a third contain `p`).
fn overlapping_blockers(g: &GBuffer, count: usize, seed: u64) -> Vec<Sphere> {
    let mut rng = TestRng(seed);
    let surface = surface_pixels(g);
    let mut out = vec![Sphere::new([0.0, 0.0, 1.0], 2.0)];
    while out.len() < count {
        let k = out.len();
        let i = surface[(rng.next() * surface.len() as f64) as usize % surface.len()];
        let p = g.position[i].map(f64::from);
        let n = unit(g.normal[i].map(f64::from));
        let r = 0.05 + 1.2 * rng.next();
        let center = match k % 8 {
            0 => add(p, n, r),
            1 => add(p, n, r * (1.0 + 1e-6)),
            2 => add(p, n, 0.5 * r),
            3 => add(p, n, -1.5 * r),
            4 => add(p, n, -0.5 * r),
            5 => p,
            _ => {
                let o = rng.vector(3, 1.5 * r);
                [p[0] + o[0], p[1] + o[1], p[2] + o[2]]
            }
        };
        out.push(Sphere::new(center, r));
    }
    out.truncate(count);
    out
}

/// Tilts `n` by `degrees` towards a tangent direction chosen from `azimuth`.
fn tilt(n: [f64; 3], degrees: f64, azimuth: f64) -> [f64; 3] {
    let helper = if n[2].abs() < 0.9 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
    let t1 = unit(cross(n, helper));
    let t2 = cross(n, t1);
    let t = add(t1.map(|c| c * azimuth.cos()), t2, azimuth.sin());
    let a = degrees.to_radians();
    unit(add(n.map(|c| c * a.cos()), t, a.sin()))
}

/// Makes most surface normals grazing, by pixel index mod 6: unchanged; tilted 89.9
/// degrees; perpendicular to the view ray; tilted exactly 90 degrees (in the plane);
/// tilted 90.1 degrees (slightly back-facing, as interpolated normals are at
/// silhouettes); tilted 89.99 degrees and stored with length 1e-3 (not normalised).
fn grazing_normals(frame: &mut Frame) {
    let eye = frame.camera.as_ref().expect("synth scenes have a camera").position;
    let g = &mut frame.gbuffer;
    for i in surface_pixels(g) {
        let n0 = unit(g.normal[i].map(f64::from));
        let p = g.position[i].map(f64::from);
        let azimuth = i as f64 * 0.7;
        let n = match i % 6 {
            0 => n0,
            1 => tilt(n0, 89.9, azimuth),
            2 => {
                let v = unit(add(eye, p, -1.0));
                let d = n0[0] * v[0] + n0[1] * v[1] + n0[2] * v[2];
                unit(add(n0, v, -d))
            }
            3 => tilt(n0, 90.0, azimuth),
            4 => tilt(n0, 90.1, azimuth),
            _ => tilt(n0, 89.99, azimuth).map(|c| 1e-3 * c),
        };
        g.normal[i] = n.map(|c| c as f32);
    }
}

/// A frame of `points` (position, normal, material) as one row of pixels, everything
/// else from `base`.
fn point_frame(base: &Frame, points: &[([f64; 3], [f64; 3], u32)]) -> Frame {
    let mut frame = base.clone();
    frame.blockers = Vec::new();
    frame.gbuffer = GBuffer {
        file: base.gbuffer.file.clone(),
        width: points.len(),
        height: 1,
        position: points.iter().map(|p| p.0.map(|c| c as f32)).collect(),
        normal: points.iter().map(|p| p.1.map(|c| c as f32)).collect(),
        uv: None,
        material: points.iter().map(|p| p.2).collect(),
        object: None,
        colours: None,
        first_row: 0,
    };
    frame
}

// ---- checks ------------------------------------------------------------------------

/// Worst values seen over a group of cases, per exponentiation method, with where they
/// were seen.
#[derive(Default)]
struct Worst(std::collections::BTreeMap<String, Entry>);

#[derive(Default)]
struct Entry {
    value: f64,
    value_at: String,
    diff: f64,
    diff_at: String,
}

impl Worst {
    fn entry(&mut self, exp: ExpMethod) -> &mut Entry {
        self.0.entry(format!("{exp:?}")).or_default()
    }
    fn value(&mut self, exp: ExpMethod, v: f64, ctx: &str) {
        let e = self.entry(exp);
        if v > e.value {
            e.value = v;
            e.value_at = ctx.to_string();
        }
    }
    fn diff(&mut self, exp: ExpMethod, d: f64, ctx: &str) {
        let e = self.entry(exp);
        if d > e.diff {
            e.diff = d;
            e.diff_at = ctx.to_string();
        }
    }
    /// Prints every method's worst and asserts `bound(method)` and the precision
    /// tolerance.
    fn report(&self, name: &str, bound: impl Fn(&str) -> f64, diff_bound: f64) {
        for (method, e) in &self.0 {
            println!(
                "{name} [{method}]: worst value {:.4} (bound {}) at {}; worst |f32 - f64| {:.2e} (bound {diff_bound:.0e}) at {}",
                e.value, bound(method), e.value_at, e.diff, e.diff_at
            );
        }
        for (method, e) in &self.0 {
            assert!(
                e.value <= bound(method),
                "{name} [{method}]: value {} > {} at {}",
                e.value,
                bound(method),
                e.value_at
            );
            assert!(e.diff <= diff_bound, "{name} [{method}]: |f32 - f64| {} at {}", e.diff, e.diff_at);
        }
    }
}

/// Shades and checks: every channel finite and >= 0, alpha 1 on surfaces and 0 on the
/// background. Returns the image and its largest surface colour channel.
fn shade_checked(scene: &Scene, frame: &Frame, settings: &ShadingSettings, ctx: &str) -> (ShadedFrame, f64) {
    let shaded = support::cpu_beauty(scene, frame, settings).unwrap_or_else(|e| panic!("{ctx}: {e}"));
    assert_eq!(shaded.rgba.len(), frame.gbuffer.material.len(), "{ctx}");
    let mut max = 0.0f64;
    for (i, (px, &m)) in shaded.rgba.iter().zip(&frame.gbuffer.material).enumerate() {
        assert!(px.iter().all(|c| c.is_finite() && *c >= 0.0), "{ctx}: pixel {i} = {px:?}");
        assert_eq!(px[3], if m == 0 { 0.0 } else { 1.0 }, "{ctx}: alpha of pixel {i}");
        if m != 0 {
            max = max.max(px[0].max(px[1]).max(px[2]) as f64);
        }
    }
    (shaded, max)
}

/// Shades in f32 and, when `compare`, in f64; records the worst value and difference.
fn shade_both(
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
    compare: bool,
    ctx: &str,
    worst: &mut Worst,
) -> ShadedFrame {
    let mut s = *settings;
    s.precision = logsh::shade::Precision::F32;
    let (single, max) = shade_checked(scene, frame, &s, ctx);
    worst.value(s.exp, max, ctx);
    if compare {
        s.precision = logsh::shade::Precision::F64;
        let (double, max) = shade_checked(scene, frame, &s, &format!("{ctx} f64"));
        worst.value(s.exp, max, &format!("{ctx} f64"));
        let d = single
            .rgba
            .iter()
            .flatten()
            .zip(double.rgba.iter().flatten())
            .map(|(a, b)| (*a as f64 - *b as f64).abs())
            .fold(0.0, f64::max);
        worst.diff(s.exp, d, ctx);
    }
    single
}

fn settings_with(order: usize, epsilon: f64, exp: ExpMethod, ratio: bool) -> ShadingSettings {
    let mut s = ShadingSettings::for_order(order);
    s.epsilon = epsilon;
    s.exp = exp;
    s.ratio_attenuation = ratio;
    s
}

// ---- blockers ----------------------------------------------------------------------

/// The methods swept here; every case stays within [`MAX_DIFFUSE`]. The SH-space ones
/// (`ol`, the Draft preset, `hyb` and `series`) stay bounded because pixels beyond
/// `sh_space_max_magnitude` are exponentiated by `quad`.
const BOUNDED_METHODS: [ExpMethod; 4] = [ExpMethod::Quad, ExpMethod::Ol, ExpMethod::Hyb, ExpMethod::Series];

#[test]
fn epsilon_order_and_ratio_sweep_over_1_50_and_402_overlapping_blockers() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, base) = base_scene(dir.path(), 16, 9);
    let mut worst = Worst::default();
    for count in [1, 50, 402] {
        let mut frame = base.clone();
        frame.blockers = overlapping_blockers(&frame.gbuffer, count, 0x5eed + count as u64);
        for order in [3, 8] {
            for epsilon in EPSILONS {
                for exp in BOUNDED_METHODS {
                    for ratio in [false, true] {
                        let ctx = format!("{count} blockers, order {order}, eps {epsilon}, {exp:?}, ratio {ratio}");
                        let s = settings_with(order, epsilon, exp, ratio);
                        shade_both(&scene, &frame, &s, true, &ctx, &mut worst);
                    }
                }
            }
        }
    }
    worst.report("sweep 1/50/402 blockers", |_| MAX_DIFFUSE, PRECISION_TOLERANCE);
}

#[test]
fn exact_exponentiation_at_extreme_epsilons() {
    // `exact` is thousands of exponentials per pixel: order 3 on the whole small frame,
    // order 8 on a row of receivers.
    let dir = tempfile::tempdir().unwrap();
    let (scene, mut frame) = base_scene(dir.path(), 16, 9);
    frame.blockers = overlapping_blockers(&frame.gbuffer, 402, 0xe7ac7);
    let mut worst = Worst::default();
    for epsilon in EPSILONS {
        for ratio in [false, true] {
            let ctx = format!("exact, order 3, eps {epsilon}, ratio {ratio}");
            shade_both(&scene, &frame, &settings_with(3, epsilon, ExpMethod::Exact, ratio), true, &ctx, &mut worst);
        }
    }
    let points: Vec<_> = (0..8).map(|k| ([k as f64 * 0.3 - 1.2, 0.1 * k as f64, 0.0], [0.0, 0.0, 1.0], 1)).collect();
    let mut row = point_frame(&frame, &points);
    row.blockers = frame.blockers.clone();
    for epsilon in [1e-6, 0.9] {
        let ctx = format!("exact, order 8, eps {epsilon}");
        shade_both(&scene, &row, &settings_with(8, epsilon, ExpMethod::Exact, false), true, &ctx, &mut worst);
    }
    worst.report("exact", |_| MAX_DIFFUSE, PRECISION_TOLERANCE);
}

/// The acceptance scene: 5000 overlapping blockers, most receivers inside one,
/// grazing normals.
fn done_when_scene(dir: &Path, width: u32, height: u32) -> (Scene, Frame) {
    let (scene, mut frame) = base_scene(dir, width, height);
    frame.blockers = overlapping_blockers(&frame.gbuffer, 5000, 0x5000);
    let inside = surface_pixels(&frame.gbuffer)
        .into_iter()
        .filter(|&i| {
            let p = frame.gbuffer.position[i].map(f64::from);
            frame.blockers.iter().any(|s| {
                let d = add(s.center, p, -1.0);
                (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() < s.radius
            })
        })
        .count();
    assert!(inside * 2 > frame.gbuffer.material.len(), "most receivers should lie inside a blocker: {inside}");
    grazing_normals(&mut frame);
    (scene, frame)
}

/// The five settings of the done-when: `--epsilon 1e-6`, `--epsilon 0.9`, `--order 8`,
/// `--quality draft`, `--quality ultra`.
fn done_when_settings() -> [(&'static str, ShadingSettings); 5] {
    let eps_small = ShadingSettings { epsilon: 1e-6, ..ShadingSettings::default() };
    let eps_large = ShadingSettings { epsilon: 0.9, ..ShadingSettings::default() };
    [
        ("--epsilon 1e-6", eps_small),
        ("--epsilon 0.9", eps_large),
        ("--order 8", ShadingSettings::for_order(8)),
        ("--quality draft", Quality::Draft.settings()),
        ("--quality ultra", Quality::Ultra.settings()),
    ]
}

/// |f32 - f64| bound where receivers have grazing normals and blockers sit on their
/// tangent planes: a blocker whose centre lies within f32 rounding of the tangent plane
/// is culled by one precision and kept by the other (`n . d <= 0`, paper 000 Section
/// 4.2), and when the receiver is inside that blocker the difference is a whole
/// hemisphere of eps. Measured 0.172 (5000 blockers, eps 0.9); bound rounded up.
const CULLING_FLIP_TOLERANCE: f64 = 0.25;

#[test]
fn five_thousand_overlapping_blockers_with_receivers_inside_and_grazing_normals() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, frame) = done_when_scene(dir.path(), 32, 18);
    let mut worst = Worst::default();
    for (name, settings) in done_when_settings() {
        // Finite, >= 0 and alpha for every setting, draft (`ol`) included.
        shade_both(&scene, &frame, &settings, true, &format!("5000 blockers, {name}"), &mut worst);
    }
    for (method, e) in &worst.0 {
        println!(
            "5000 blockers (done-when) [{method}]: worst value {:.4} at {}; worst |f32 - f64| {:.2e} at {}",
            e.value, e.value_at, e.diff, e.diff_at
        );
        assert!(e.diff <= CULLING_FLIP_TOLERANCE, "[{method}] |f32 - f64| {} at {}", e.diff, e.diff_at);
    }
    let quad = &worst.0["Quad"];
    assert!(quad.value <= MAX_DIFFUSE, "quad: {} at {}", quad.value, quad.value_at);
}

#[test]
fn five_thousand_blockers_across_epsilons_and_orders() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, frame) = done_when_scene(dir.path(), 12, 7);
    let mut worst = Worst::default();
    for order in [3, 8] {
        for epsilon in EPSILONS {
            for ratio in [false, true] {
                let ctx = format!("5000 blockers, order {order}, eps {epsilon}, ratio {ratio}");
                shade_both(
                    &scene,
                    &frame,
                    &settings_with(order, epsilon, ExpMethod::Quad, ratio),
                    true,
                    &ctx,
                    &mut worst,
                );
            }
        }
    }
    for (method, e) in &worst.0 {
        println!(
            "5000 blockers sweep [{method}]: worst value {:.4} at {}; worst |f32 - f64| {:.2e} at {}",
            e.value, e.value_at, e.diff, e.diff_at
        );
        assert!(e.value <= MAX_DIFFUSE && e.diff <= PRECISION_TOLERANCE);
    }
}

#[test]
fn receivers_inside_touching_and_just_outside_one_blocker() {
    // Receivers at x = 1e4 k facing +Z, each with one blocker of radius 1 above it whose
    // centre moves from inside (the receiver inside the sphere) through touching to just
    // outside; the other receivers' blockers are 1e4 away (caps of 1e-4 rad, log
    // contributions below 1e-7). Inside and touching see the hemisphere (alpha = pi/2);
    // just outside sees alpha = asin(1 / (1 + d)): the value is continuous across the
    // surface.
    let dir = tempfile::tempdir().unwrap();
    let (scene, base) = base_scene(dir.path(), 8, 4);
    let heights = [0.25, 0.5, 0.999, 1.0 - 1e-7, 1.0, 1.0 + 1e-7, 1.0 + 1e-6, 1.0 + 1e-3, 1.01];
    let points: Vec<_> = (0..heights.len()).map(|k| ([1e4 * k as f64, 0.0, 0.0], [0.0, 0.0, 1.0], 1)).collect();
    let mut frame = point_frame(&base, &points);
    frame.blockers = heights.iter().enumerate().map(|(k, &z)| Sphere::new([1e4 * k as f64, 0.0, z], 1.0)).collect();
    let mut worst = Worst::default();
    for order in [3, 8] {
        for epsilon in EPSILONS {
            // `ol` and `hyb` fit an OL table per run (slow at order 8): order 3 only.
            let methods: &[ExpMethod] =
                if order == 3 { &[ExpMethod::Quad, ExpMethod::Hyb, ExpMethod::Ol] } else { &[ExpMethod::Quad] };
            for &exp in methods {
                for ratio in [false, true] {
                    let ctx = format!("order {order}, eps {epsilon}, {exp:?}, ratio {ratio}");
                    let s = settings_with(order, epsilon, exp, ratio);
                    let values: Vec<f64> = shade_both(&scene, &frame, &s, true, &ctx, &mut worst)
                        .rgba
                        .iter()
                        .map(|p| p[0] as f64)
                        .collect();
                    let touching = values[4];
                    for (z, v) in heights.iter().zip(&values) {
                        if *z <= 1.0 {
                            // Inside or touching: the same hemisphere, the same value.
                            assert!((v - touching).abs() <= 1e-6, "{ctx}: inside at z {z}: {v} vs touching {touching}");
                        }
                    }
                    // Continuity across the surface: 1e-6 outside changes alpha by 1.4e-3.
                    let just_outside = values[6];
                    assert!(
                        (just_outside - touching).abs() <= 0.02,
                        "{ctx}: touching {touching}, just outside {just_outside}"
                    );
                }
            }
        }
    }
    worst.report("one blocker inside/touching/outside", |_| MAX_DIFFUSE, PRECISION_TOLERANCE);
}

#[test]
fn blockers_behind_the_surface_change_nothing() {
    // Spheres whose centres lie on or behind the tangent plane are culled (paper 000,
    // end of Section 4.2), including ones that contain the receiver and one centred on
    // it: the result must equal the unoccluded one bit for bit.
    let dir = tempfile::tempdir().unwrap();
    let (scene, base) = base_scene(dir.path(), 8, 4);
    let normals = [[0.0, 0.0, 1.0], tilt([0.0, 0.0, 1.0], 60.0, 0.3), tilt([0.0, 0.0, 1.0], 89.9, 1.0)];
    let p = [0.5, -0.25, 0.0];
    let points: Vec<_> = normals.iter().map(|&n| (p, n, 1)).collect();
    let frame = point_frame(&base, &points);
    let mut behind = frame.clone();
    let mut rng = TestRng(0xbe41d);
    behind.blockers.push(Sphere::new(p, 0.5));
    for n in normals {
        behind.blockers.push(Sphere::new(add(p, n, -1e-6), 3.0));
        for _ in 0..200 {
            let r = 0.01 + 2.0 * rng.next();
            let d = unit([rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5]);
            let along = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
            let d = if along > 0.0 { d.map(|c| -c) } else { d };
            behind.blockers.push(Sphere::new(add(p, d, 0.01 + 5.0 * rng.next()), r));
        }
    }
    // Keep only blockers behind every receiver's tangent plane.
    behind.blockers.retain(|s| {
        let d = add(s.center, p, -1.0);
        normals.iter().all(|n| d[0] * n[0] + d[1] * n[1] + d[2] * n[2] <= 0.0)
    });
    assert!(behind.blockers.len() > 100, "{}", behind.blockers.len());
    for order in [3, 8] {
        for epsilon in [1e-6, 0.9] {
            let methods: &[ExpMethod] = if order == 3 { &CHEAP_METHODS } else { &BOUNDED_METHODS };
            for &exp in methods {
                let s = settings_with(order, epsilon, exp, false);
                let ctx = format!("order {order}, eps {epsilon}, {exp:?}");
                let (clear, _) = shade_checked(&scene, &frame, &s, &ctx);
                let (culled, _) = shade_checked(&scene, &behind, &s, &ctx);
                assert_eq!(clear.rgba, culled.rgba, "{ctx}: blockers behind the surface changed the result");
            }
        }
    }
}

#[test]
fn grazing_normals_and_degenerate_normal_lengths() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, base) = base_scene(dir.path(), 8, 4);
    let up = [0.0, 0.0, 1.0];
    let mut points = Vec::new();
    for (k, degrees) in [0.0, 45.0, 80.0, 89.0, 89.9, 89.99, 90.0, 90.01, 90.1, 135.0, 180.0].into_iter().enumerate() {
        points.push(([0.1 * k as f64, 0.0, 0.0], tilt(up, degrees, 0.5 * k as f64), 1));
    }
    // Not normalised: tiny, huge, zero (the shader falls back to +Z) and subnormal.
    points.push(([0.0, 0.5, 0.0], [0.0, 1e-20, 1e-20], 1));
    points.push(([0.0, 0.6, 0.0], [1e30, 0.0, 1e30], 1));
    points.push(([0.0, 0.7, 0.0], [0.0, 0.0, 0.0], 1));
    points.push(([0.0, 0.8, 0.0], [1e-40, 0.0, 0.0], 1));
    let clear = point_frame(&base, &points);
    let mut blocked = clear.clone();
    blocked.blockers = overlapping_blockers(&clear.gbuffer, 402, 0x9a2e);
    let mut worst = Worst::default();
    for frame in [&clear, &blocked] {
        for order in [3, 8] {
            for epsilon in EPSILONS {
                // Every method unoccluded at order 3 (finite; `ol`, `hyb` and `series` are not
                // bounded, see the bug tests); `quad` everywhere.
                let methods: &[ExpMethod] =
                    if frame.blockers.is_empty() && order == 3 { &CHEAP_METHODS } else { &BOUNDED_METHODS };
                for &exp in methods {
                    let ctx = format!("{} blockers, order {order}, eps {epsilon}, {exp:?}", frame.blockers.len());
                    shade_both(&scene, frame, &settings_with(order, epsilon, exp, false), true, &ctx, &mut worst);
                }
            }
        }
    }
    worst.report("grazing normals", |_| MAX_DIFFUSE, PRECISION_TOLERANCE);
}

// ---- Phong -------------------------------------------------------------------------

#[test]
fn phong_exponents_from_1_to_1024() {
    let dir = tempfile::tempdir().unwrap();
    let (mut scene, mut frame) = base_scene(dir.path(), 10, 6);
    let exponents = [1.0f32, 16.0, 256.0, 1024.0];
    for (k, &exponent) in exponents.iter().enumerate() {
        scene.materials.insert(10 + k as u32, Material::Phong { albedo: [0.0; 3], specular: [1.0; 3], exponent });
    }
    frame.blockers = overlapping_blockers(&frame.gbuffer, 50, 0xf0);
    grazing_normals(&mut frame);
    let mut worst = Worst::default();
    for (k, exponent) in exponents.iter().enumerate() {
        let mut f = frame.clone();
        for m in f.gbuffer.material.iter_mut().filter(|m| **m != 0) {
            *m = 10 + k as u32;
        }
        for blocked in [false, true] {
            let mut f = f.clone();
            if !blocked {
                f.blockers.clear();
            }
            for order in [3, 8] {
                for epsilon in EPSILONS {
                    for exp in BOUNDED_METHODS {
                        let ctx =
                            format!("phong {exponent}, blockers {blocked}, order {order}, eps {epsilon}, {exp:?}");
                        shade_both(&scene, &f, &settings_with(order, epsilon, exp, false), true, &ctx, &mut worst);
                    }
                }
            }
        }
    }
    worst.report("phong", |_| MAX_PHONG, PHONG_PRECISION_TOLERANCE);
}

// ---- height fields -----------------------------------------------------------------

/// A height-field frame: the base frame's plane pixels lifted onto `map` (material 20,
/// `heightfield`), normals from central differences, plus receivers on a vertical face
/// at `x = cliff_x` when given (normal -X, exactly horizontal) and at its foot.
fn height_field_frame(base: &Frame, map: HeightMap, cliff_x: Option<f64>) -> Frame {
    let mut frame = base.clone();
    let g = &mut frame.gbuffer;
    let h =
        |x: f64, y: f64| if map.columns >= 2 && map.rows >= 2 { map.height_at(x, y) } else { map.heights[0] as f64 };
    for i in surface_pixels(g) {
        let [x, y, _] = g.position[i].map(f64::from);
        let d = 1e-3;
        let nx = -(h(x + d, y) - h(x - d, y)) / (2.0 * d);
        let ny = -(h(x, y + d) - h(x, y - d)) / (2.0 * d);
        g.position[i] = [x as f32, y as f32, h(x, y) as f32];
        g.normal[i] = unit([nx, ny, 1.0]).map(|c| c as f32);
        g.material[i] = 20;
    }
    if let Some(cx) = cliff_x {
        // Every 5th pixel of the top rows: on the face, at its foot, on its top edge.
        let (lo, hi) = (h(cx - 1.0, 0.0), h(cx + 1.0, 0.0));
        for k in 0..g.width {
            let t = k as f64 / g.width as f64;
            let (p, n) = match k % 3 {
                0 => ([cx, t * 4.0 - 2.0, lo + (hi - lo) * t], [-1.0, 0.0, 0.0]),
                1 => ([cx - 1e-4, t * 4.0 - 2.0, lo], [0.0, 0.0, 1.0]),
                _ => ([cx + 0.05, t * 4.0 - 2.0, hi], [0.0, 0.0, 1.0]),
            };
            g.position[k] = p.map(|c| c as f32);
            g.normal[k] = n.map(|c| c as f32);
            g.material[k] = 20;
        }
    }
    frame.height_map = Some(Arc::new(map));
    frame
}

#[test]
fn height_fields_vertical_cliff_flat_and_single_sample() {
    let dir = tempfile::tempdir().unwrap();
    let (mut scene, base) = base_scene(dir.path(), 12, 7);
    scene.materials.insert(20, Material::Heightfield { albedo: [1.0; 3] });
    let (min, max) = ([-8.0, -8.0], [8.0, 8.0]);
    // A step of 3 across one cell of 1/16: 88.8 degrees, as vertical as a
    // corner-registered bilinear map gets.
    let cliff = HeightMap::from_fn(257, 257, min, max, |x, _| if x < 0.0 { 0.0 } else { 3.0 });
    let flat = HeightMap::from_fn(33, 33, min, max, |_, _| 0.0);
    let single = HeightMap { heights: vec![0.0], columns: 1, rows: 1, min, max };
    let frames = [
        ("cliff", height_field_frame(&base, cliff, Some(0.0))),
        ("flat", height_field_frame(&base, flat, None)),
        ("1x1", height_field_frame(&base, single, None)),
    ];
    let mut worst = Worst::default();
    for (name, frame) in &frames {
        for with_blockers in [false, true] {
            let mut frame = frame.clone();
            frame.blockers = if with_blockers { overlapping_blockers(&frame.gbuffer, 50, 0xc11f) } else { vec![] };
            for quality in Quality::ALL {
                for epsilon in EPSILONS {
                    if quality == Quality::High && epsilon != 1e-6 && epsilon != 0.9 {
                        continue;
                    }
                    let mut s = quality.settings();
                    s.epsilon = epsilon;
                    let ctx = format!("{name}, blockers {with_blockers}, {}, eps {epsilon}", quality.name());
                    let shaded = shade_both(&scene, &frame, &s, true, &ctx, &mut worst);
                    if *name != "cliff" && !with_blockers && s.exp == ExpMethod::Quad {
                        // A flat map occludes nothing: every receiver sees the open sky.
                        for (px, &m) in shaded.rgba.iter().zip(&frame.gbuffer.material) {
                            assert!(m == 0 || px[0] > 0.5, "{ctx}: unoccluded flat terrain at {}", px[0]);
                        }
                    }
                }
            }
        }
    }
    worst.report("height fields", |_| MAX_DIFFUSE, PRECISION_TOLERANCE);
}

#[test]
fn single_sample_height_map_file_is_refused_clearly() {
    // In memory a 1x1 map is accepted (above); the reader requires 2x2 (docs/design.md).
    let dir = tempfile::tempdir().unwrap();
    base_scene(dir.path(), 8, 4);
    let map = HeightMap { heights: vec![0.0], columns: 1, rows: 1, min: [0.0, 0.0], max: [1.0, 1.0] };
    synth::write_height_map_exr(&dir.path().join("heightmap.exr"), &map).unwrap();
    let file = dir.path().join("scene.json");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    json["heightfield"] = serde_json::json!({"heights": "heightmap.exr", "min": [-1.0, -1.0], "max": [1.0, 1.0]});
    std::fs::write(&file, serde_json::to_string(&json).unwrap()).unwrap();
    let text = Scene::load(dir.path()).expect_err("a 1x1 height map file is refused").to_string();
    assert!(text.contains("heightmap.exr") && text.contains("1x1") && text.contains("2x2"), "{text}");
}

// ---- runaways of the SH-space exponentiations, fixed --------------------------------
// OL, HYB and the series ran away here (HYB to inf, OL to 30-80, the series to 6e10)
// until pixels beyond `sh_space_max_magnitude` were handed to `quad`
// (src/shade/kernel.rs); these keep them bounded.

#[test]
fn hyb_stays_bounded_with_5000_blockers_at_small_epsilon() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, frame) = done_when_scene(dir.path(), 12, 7);
    for double in [false, true] {
        let mut s = settings_with(3, 1e-6, ExpMethod::Hyb, false);
        s.precision = if double { logsh::shade::Precision::F64 } else { logsh::shade::Precision::F32 };
        let (_, max) = shade_checked(&scene, &frame, &s, &format!("hyb, 5000 blockers, eps 1e-6, f64 {double}"));
        assert!(max <= MAX_DIFFUSE, "hyb: {max}");
    }
}

#[test]
fn draft_stays_bounded_on_the_done_when_scene() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, frame) = done_when_scene(dir.path(), 32, 18);
    let (_, max) = shade_checked(&scene, &frame, &Quality::Draft.settings(), "draft, 5000 blockers");
    assert!(max <= MAX_DIFFUSE, "draft (ol): {max}");
}

#[test]
fn series_stays_bounded_with_402_blockers() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, base) = base_scene(dir.path(), 8, 4);
    let points: Vec<_> = (0..11).map(|k| ([0.1 * k as f64, 0.0, 0.0], [0.0, 0.0, 1.0], 1)).collect();
    let mut frame = point_frame(&base, &points);
    frame.blockers = overlapping_blockers(&frame.gbuffer, 402, 0x9a2e);
    let (_, max) = shade_checked(&scene, &frame, &settings_with(8, 0.5, ExpMethod::Series, false), "series");
    assert!(max <= MAX_DIFFUSE, "series: {max}");
}

// ---- non-finite G-buffers ----------------------------------------------------------

/// Rewrites the scene's G-buffer after `edit`.
fn rewrite_gbuffer(dir: &Path, frame: &Frame, edit: impl FnOnce(&mut GBuffer)) {
    let mut g = frame.gbuffer.clone();
    edit(&mut g);
    synth::write_gbuffer_exr(&dir.join("gbuffer.0001.exr"), &g, GBufferLayout::Blender5).unwrap();
}

#[test]
fn non_finite_gbuffer_values_are_a_clear_error_on_surfaces_and_ignored_on_the_background() {
    // Documented (scene::gbuffer): position and normal must be finite on every
    // non-background pixel, an error naming the file, the pixel and the value; the
    // background (material 0) is not checked, its position and normal are never read.
    let dir = tempfile::tempdir().unwrap();
    let (_, frame) = base_scene(dir.path(), 16, 9);
    let (x, y) = (5, 3);
    let i = y * 16 + x;
    assert_ne!(frame.gbuffer.material[i], 0);
    type Corruption = (&'static str, Box<dyn Fn(&mut GBuffer)>);
    let cases: [Corruption; 4] = [
        ("position", Box::new(move |g: &mut GBuffer| g.position[i][0] = f32::NAN)),
        ("position", Box::new(move |g: &mut GBuffer| g.position[i][2] = f32::NEG_INFINITY)),
        ("normal", Box::new(move |g: &mut GBuffer| g.normal[i][1] = f32::INFINITY)),
        ("normal", Box::new(move |g: &mut GBuffer| g.normal[i] = [f32::NAN; 3])),
    ];
    for (what, edit) in &cases {
        rewrite_gbuffer(dir.path(), &frame, edit);
        let err = Scene::load(dir.path()).unwrap().frame(1).expect_err("a non-finite surface pixel must be refused");
        assert!(matches!(err, SceneError::NonFinite { .. }), "{err:?}");
        let text = err.to_string();
        for part in ["gbuffer.0001.exr", what, &format!("pixel ({x}, {y})"), "not a finite number"] {
            assert!(text.contains(part), "error {text:?} should mention {part:?}");
        }
    }

    // The same values on background pixels: accepted, shaded as background (alpha 0).
    rewrite_gbuffer(dir.path(), &frame, |g| {
        for (k, j) in [0usize, 1, 2, i].into_iter().enumerate() {
            g.material[j] = 0;
            g.position[j] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
            g.normal[j] = if k % 2 == 0 { [f32::NAN; 3] } else { [f32::INFINITY, 0.0, f32::NAN] };
        }
    });
    let scene = Scene::load(dir.path()).unwrap();
    let mut frame = scene.frame(1).expect("non-finite background pixels are accepted");
    frame.blockers = overlapping_blockers(&frame.gbuffer, 50, 0xbad);
    for quality in Quality::ALL {
        let (shaded, _) = shade_checked(&scene, &frame, &quality.settings(), quality.name());
        assert_eq!(shaded.rgba[i][3], 0.0);
    }
}

// ---- bounce light ------------------------------------------------------------------

/// A closed pit: the plane's pixels lifted onto a bowl 6 deep (material 20,
/// `heightfield`), the sphere floating in it, every albedo `albedo`, under the base
/// scene's constant white light.
fn pit(dir: &Path, albedo: f32) -> (Scene, Frame) {
    let (mut scene, base) = base_scene(dir, 24, 14);
    for material in scene.materials.values_mut() {
        if let Material::Diffuse { albedo: a } | Material::Heightfield { albedo: a } = material {
            *a = [albedo; 3];
        }
    }
    scene.materials.insert(20, Material::Heightfield { albedo: [albedo; 3] });
    let bowl = HeightMap::from_fn(65, 65, [-8.0, -8.0], [8.0, 8.0], |x, y| 0.1 * (x * x + y * y).min(60.0));
    (scene, height_field_frame(&base, bowl, None))
}

/// The frame's passes with `bounces` bounces, on the CPU executor, every value of every
/// colour pass checked finite and `>= 0`.
fn bounced(scene: &Scene, frame: &Frame, bounces: usize, ctx: &str) -> ShadedPasses {
    let settings =
        ShadingSettings { bounce: BounceSettings { bounces, ..BounceSettings::DEFAULT }, ..ShadingSettings::default() };
    let passes =
        support::rendered_passes(&Executor::cpu(), scene, frame, &settings).unwrap_or_else(|e| panic!("{ctx}: {e}"));
    for (name, pass) in [
        ("diffuse", &passes.diffuse),
        ("indirect", &passes.indirect),
        ("indirect_heightfield", &passes.indirect_heightfield),
        ("indirect_blockers", &passes.indirect_blockers),
    ] {
        for (i, v) in pass.iter().enumerate() {
            assert!(v.iter().all(|c| c.is_finite() && *c >= 0.0), "{ctx}: {name} of pixel {i} is {v:?}");
        }
    }
    passes
}

/// The mean and largest beauty channel over the surface pixels.
fn surface_stats(frame: &Frame, passes: &ShadedPasses) -> (f64, f64) {
    let pixels = surface_pixels(&frame.gbuffer);
    let values: Vec<f64> = pixels.iter().flat_map(|&i| passes.beauty[i][..3].iter().map(|&c| f64::from(c))).collect();
    (values.iter().sum::<f64>() / values.len() as f64, values.iter().copied().fold(0.0, f64::max))
}

/// A white furnace: in a closed pit whose every surface has albedo 1, under a white sky
/// of radiance 1, the exact radiance is 1 everywhere once every bounce is counted. Each
/// bounce must raise the frame towards it by less than the one before (a convergent
/// series, not a runaway), and no pixel may exceed 1 by more than the direct light's own
/// SH ringing allows (bound 1.05; measured: means 0.70, 0.91, 0.98, 1.01 for 0 to 3
/// bounces, largest 1.027, the direct light's own).
#[test]
fn bounce_light_converges_in_a_white_furnace() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, frame) = pit(dir.path(), 1.0);
    let mut means = Vec::new();
    for bounces in 0..=3 {
        let passes = bounced(&scene, &frame, bounces, &format!("white pit, {bounces} bounces"));
        let (mean, max) = surface_stats(&frame, &passes);
        println!("white pit, {bounces} bounces: mean {mean:.4}, largest {max:.4}");
        assert!(max <= 1.05, "{bounces} bounces: a pixel of {max} in a white furnace");
        means.push(mean);
    }
    let steps: Vec<f64> = means.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(steps.iter().all(|&s| s > 0.0), "each bounce adds light: {means:?}");
    assert!(steps.windows(2).all(|w| w[1] < w[0]), "each bounce adds less than the one before: {means:?}");
}

/// Black surfaces reflect no bounce light; a sun of 1e6 gives bounce light 1e6 times a
/// sun of 1 (the bounce is linear in the light, and f32 holds it); a sun on the horizon
/// and one below it leave every value finite.
#[test]
fn bounce_light_off_black_surfaces_and_under_extreme_suns() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, frame) = pit(dir.path(), 0.0);
    let black = bounced(&scene, &frame, 3, "black pit");
    assert!(black.indirect.iter().all(|v| *v == [0.0; 3]), "a black pit reflects bounce light");

    let (scene, mut frame) = pit(dir.path(), 0.7);
    frame.light = Arc::new(logsh::scene::Light::Constant([0.0; 3]));
    let sun = |elevation: f64, strength: f32| {
        let e = elevation.to_radians();
        SunLight { direction: [0.6 * e.cos(), 0.8 * e.cos(), e.sin()], half_angle: 0.0047, strength, color: [1.0; 3] }
    };
    let mut indirect = Vec::new();
    for strength in [1.0, 1e6] {
        frame.suns = vec![sun(35.0, strength)];
        indirect.push(bounced(&scene, &frame, 2, &format!("sun of {strength}")).indirect);
    }
    let (one, million) = (&indirect[0], &indirect[1]);
    assert!(one.iter().any(|v| v[0] > 1e-3), "the sun's bounce light");
    let worst = one
        .iter()
        .zip(million)
        .flat_map(|(a, b)| (0..3).map(move |c| (f64::from(b[c]) / 1e6 - f64::from(a[c])).abs()))
        .fold(0.0, f64::max);
    println!("a sun of 1e6 against one of 1: worst |indirect / 1e6 - indirect| {worst:.2e}");
    assert!(worst <= 1e-4, "a sun of 1e6 does not scale the bounce: {worst}");
    for elevation in [0.0, -3.0] {
        frame.suns = vec![sun(elevation, 5.0)];
        bounced(&scene, &frame, 3, &format!("a sun at {elevation} deg"));
    }
}
