//! Analytic primitives and the ray caster that turns them into G-buffers.

use crate::scene::{Camera, GBuffer, HeightMap};
use crate::vector::{cross, dot, normalize, sub};
use rayon::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// A surface the ray caster can hit. Every normal faces outward (planes: +Z).
#[derive(Clone, Debug)]
pub enum Shape {
    /// The horizontal plane at height `z`, optionally limited to the XY rectangle
    /// `bounds.0 ..= bounds.1`.
    Plane {
        z: f64,
        bounds: Option<([f64; 2], [f64; 2])>,
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    /// A solid cone: disk of `radius` at `base`, tip at `apex`.
    Cone {
        base: [f64; 3],
        apex: [f64; 3],
        radius: f64,
    },
    /// The height field of a map (bilinear, flat beyond its rectangle as the format says).
    Terrain(Arc<HeightMap>),
}

/// A shape with its material index.
#[derive(Clone, Debug)]
pub struct Object {
    pub shape: Shape,
    pub material: u32,
}

/// The nearest intersection of a ray.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f64,
    pub position: [f64; 3],
    pub normal: [f64; 3],
    pub uv: [f64; 2],
    pub material: u32,
}

fn at(o: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
    [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]
}

/// Nearest hit along `origin + t dir`, `t > t_min`; `dir` must be unit.
pub fn trace(objects: &[Object], origin: [f64; 3], dir: [f64; 3], t_min: f64) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for obj in objects {
        let t_max = best.map_or(f64::INFINITY, |h| h.t);
        if let Some(mut h) = intersect(&obj.shape, origin, dir, t_min, t_max) {
            h.material = obj.material;
            best = Some(h);
        }
    }
    best
}

fn intersect(shape: &Shape, o: [f64; 3], d: [f64; 3], t_min: f64, t_max: f64) -> Option<Hit> {
    let ok = |t: f64| t > t_min && t < t_max;
    match shape {
        Shape::Plane { z, bounds } => {
            if d[2].abs() < 1e-15 {
                return None;
            }
            let t = (z - o[2]) / d[2];
            if !ok(t) {
                return None;
            }
            let p = at(o, d, t);
            if let Some((lo, hi)) = bounds {
                if p[0] < lo[0] || p[0] > hi[0] || p[1] < lo[1] || p[1] > hi[1] {
                    return None;
                }
            }
            Some(Hit {
                t,
                position: p,
                normal: [0.0, 0.0, 1.0],
                uv: [p[0].rem_euclid(1.0), p[1].rem_euclid(1.0)],
                material: 0,
            })
        }
        Shape::Sphere { center, radius } => {
            let oc = sub(o, *center);
            let b = dot(oc, d);
            let c = dot(oc, oc) - radius * radius;
            let disc = b * b - c;
            if disc < 0.0 {
                return None;
            }
            let s = disc.sqrt();
            let t = [-b - s, -b + s].into_iter().find(|&t| ok(t))?;
            let p = at(o, d, t);
            let n = normalize(sub(p, *center));
            let uv = [
                0.5 + n[1].atan2(n[0]) / (2.0 * std::f64::consts::PI),
                n[2].clamp(-1.0, 1.0).acos() / std::f64::consts::PI,
            ];
            Some(Hit { t, position: p, normal: n, uv, material: 0 })
        }
        Shape::Cone { base, apex, radius } => intersect_cone(*base, *apex, *radius, o, d, t_min, t_max),
        Shape::Terrain(map) => {
            let t = march_terrain(map, o, d, t_min, t_max)?;
            let p = at(o, d, t);
            let [cx, cy] = map.cell_size();
            let dhdx = (map.height_at(p[0] + cx, p[1]) - map.height_at(p[0] - cx, p[1])) / (2.0 * cx);
            let dhdy = (map.height_at(p[0], p[1] + cy) - map.height_at(p[0], p[1] - cy)) / (2.0 * cy);
            let n = normalize([-dhdx, -dhdy, 1.0]);
            let uv = [(p[0] - map.min[0]) / (map.max[0] - map.min[0]), (p[1] - map.min[1]) / (map.max[1] - map.min[1])];
            Some(Hit { t, position: p, normal: n, uv, material: 0 })
        }
    }
}

fn intersect_cone(
    base: [f64; 3],
    apex: [f64; 3],
    radius: f64,
    o: [f64; 3],
    d: [f64; 3],
    t_min: f64,
    t_max: f64,
) -> Option<Hit> {
    let axis = sub(base, apex);
    let height = dot(axis, axis).sqrt();
    let v = normalize(axis); // apex -> base
    let cos2 = height * height / (height * height + radius * radius);
    let co = sub(o, apex);
    let (dv, cov) = (dot(d, v), dot(co, v));
    let a = dv * dv - cos2;
    let b = 2.0 * (dv * cov - dot(d, co) * cos2);
    let c = cov * cov - dot(co, co) * cos2;
    let mut best: Option<(f64, [f64; 3])> = None;
    let mut consider = |t: f64, n: [f64; 3]| {
        if t > t_min && t < t_max && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, n));
        }
    };
    let disc = b * b - 4.0 * a * c;
    if disc >= 0.0 && a.abs() > 1e-15 {
        let s = disc.sqrt();
        for t in [(-b - s) / (2.0 * a), (-b + s) / (2.0 * a)] {
            let p = at(o, d, t);
            let cp = sub(p, apex);
            let h = dot(cp, v);
            if h >= 0.0 && h <= height {
                // Outward normal: radial * cos(half angle) - axis * sin(half angle).
                let radial = sub(cp, [v[0] * h, v[1] * h, v[2] * h]);
                let rl = dot(radial, radial).sqrt();
                if rl > 0.0 {
                    let slant = (height * height + radius * radius).sqrt();
                    let (ca, sa) = (height / slant, radius / slant);
                    let r = [radial[0] / rl, radial[1] / rl, radial[2] / rl];
                    consider(t, [r[0] * ca - v[0] * sa, r[1] * ca - v[1] * sa, r[2] * ca - v[2] * sa]);
                }
            }
        }
    }
    // Base disk, normal along +v (away from the apex).
    if dv.abs() > 1e-15 {
        let t = dot(sub(base, o), v) / dv;
        let p = at(o, d, t);
        let q = sub(p, base);
        if dot(q, q) <= radius * radius {
            consider(t, v);
        }
    }
    let (t, n) = best?;
    let p = at(o, d, t);
    let side = normalize(cross(v, if v[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] }));
    let q = sub(p, apex);
    let uv = [0.5 + dot(q, cross(v, side)).atan2(dot(q, side)) / (2.0 * std::f64::consts::PI), dot(q, v) / height];
    Some(Hit { t, position: p, normal: n, uv, material: 0 })
}

/// First crossing of the ray below the terrain: steps of half a cell in XY, then
/// bisection to 1e-9 of the step. Looks no farther than three times the map's size past
/// its rectangle (beyond, a ray is taken to reach the sky). A ray starting below the
/// surface hits nothing.
fn march_terrain(map: &HeightMap, o: [f64; 3], d: [f64; 3], t_min: f64, t_max: f64) -> Option<f64> {
    let (lo, hi) = map.range();
    let (lo, hi) = (lo - 1e-9, hi + 1e-9);
    let (mut t0, mut t1) = if d[2].abs() < 1e-15 {
        if o[2] < lo || o[2] > hi {
            return None;
        }
        (f64::NEG_INFINITY, f64::INFINITY)
    } else {
        let (ta, tb) = ((lo - o[2]) / d[2], (hi - o[2]) / d[2]);
        (ta.min(tb), ta.max(tb))
    };
    let size = (map.max[0] - map.min[0]).max(map.max[1] - map.min[1]);
    let centre = [(map.min[0] + map.max[0]) / 2.0, (map.min[1] + map.max[1]) / 2.0];
    let dxy = (d[0] * d[0] + d[1] * d[1]).sqrt();
    if dxy > 1e-12 {
        let oxy = ((o[0] - centre[0]).powi(2) + (o[1] - centre[1]).powi(2)).sqrt();
        t1 = t1.min((oxy + 3.5 * size) / dxy);
    }
    t0 = t0.max(t_min);
    t1 = t1.min(t_max).min(1e7);
    if t0.is_nan() || t1.is_nan() || t0 >= t1 {
        return None;
    }
    let f = |t: f64| {
        let p = at(o, d, t);
        p[2] - map.height_at(p[0], p[1])
    };
    let [cx, cy] = map.cell_size();
    let dt = if dxy > 1e-12 { 0.5 * cx.min(cy) / dxy } else { t1 - t0 };
    let mut ta = t0;
    if f(ta) < 0.0 {
        return None;
    }
    loop {
        let tb = (ta + dt).min(t1);
        if f(tb) <= 0.0 {
            let (mut a, mut b) = (ta, tb);
            for _ in 0..50 {
                let m = 0.5 * (a + b);
                if f(m) > 0.0 {
                    a = m;
                } else {
                    b = m;
                }
                if b - a < 1e-9 * dt.max(1e-6) {
                    break;
                }
            }
            return Some(b);
        }
        if tb >= t1 {
            return None;
        }
        ta = tb;
    }
}

/// Position, normal, UV and material of one pixel.
type Sample = ([f32; 3], [f32; 3], [f32; 2], u32);

/// One G-buffer sample; background is all zero.
fn sample(hit: Option<Hit>) -> Sample {
    match hit {
        None => ([0.0; 3], [0.0; 3], [0.0; 2], 0),
        Some(h) => (
            h.position.map(|v| v as f32),
            h.normal.map(|v| v as f32),
            h.uv.map(|v| exr::prelude::f16::from_f64(v).to_f32()),
            h.material,
        ),
    }
}

fn gbuffer_from(width: usize, height: usize, samples: Vec<Sample>) -> GBuffer {
    GBuffer {
        file: PathBuf::new(),
        width,
        height,
        position: samples.iter().map(|s| s.0).collect(),
        normal: samples.iter().map(|s| s.1).collect(),
        uv: Some(samples.iter().map(|s| s.2).collect()),
        material: samples.iter().map(|s| s.3).collect(),
        object: None,
        colours: None,
        first_row: 0,
    }
}

/// Casts one ray through the centre of every pixel. UV values are rounded to f16, as
/// they are stored, so that a written and re-read buffer equals this one.
pub fn render_gbuffer(objects: &[Object], camera: &Camera) -> GBuffer {
    let (w, h) = (camera.resolution[0] as usize, camera.resolution[1] as usize);
    let samples: Vec<_> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let d = camera.ray_direction((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            sample(trace(objects, camera.position, d, 0.0))
        })
        .collect();
    gbuffer_from(w, h, samples)
}

/// The reflection G-buffer: for each pixel of `primary` whose material is in `mirrors`,
/// the surface seen along the view ray mirrored about the normal (the mirror itself
/// excluded); background elsewhere.
pub fn render_reflection(objects: &[Object], primary: &GBuffer, camera: &Camera, mirrors: &[u32]) -> GBuffer {
    let others: Vec<Object> = objects.iter().filter(|o| !mirrors.contains(&o.material)).cloned().collect();
    let samples: Vec<_> = (0..primary.width * primary.height)
        .into_par_iter()
        .map(|i| {
            if !mirrors.contains(&primary.material[i]) {
                return sample(None);
            }
            let p = primary.position[i].map(|v| v as f64);
            let n = normalize(primary.normal[i].map(|v| v as f64));
            let v = normalize(sub(p, camera.position));
            let k = 2.0 * dot(v, n);
            let r = normalize([v[0] - k * n[0], v[1] - k * n[1], v[2] - k * n[2]]);
            let origin = [p[0] + 1e-4 * n[0], p[1] + 1e-4 * n[1], p[2] + 1e-4 * n[2]];
            sample(trace(&others, origin, r, 1e-6))
        })
        .collect();
    gbuffer_from(primary.width, primary.height, samples)
}
