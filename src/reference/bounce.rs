//! Bounce light in the reference: paths of up to `bounces` bounces off the same proxies
//! the fast path reflects from (the height field or the ground plane, and the blocker
//! spheres), with their albedos and the spheres' specular reflectances baked the same
//! way ([`SurfaceAlbedos`](crate::shade::bounce::SurfaceAlbedos)). The terrain reflects
//! diffusely; a sphere diffusely and as a mirror of its object's specular reflectance
//! (the fast path's mirror-ball mean, traced exactly: the mirrored ray's own first hit,
//! or the light along it, with the Sun lamps' disks).
//!
//! At a receiver, `samples` directions are drawn by the cosine (stratified on a square
//! grid, jittered by the pixel's seed); each ray's first hit, exact for the spheres and
//! the ground plane, found on the bilinear height field by [`terrain_hit`] (steps of a
//! quarter sample), reflects its albedo times its own direct light (the reference's
//! integration with exact visibility, to four times the pixel's tolerance) and, with
//! bounces left, its own bounce. The mean over the rays is `E / pi` (the cosine's pdf is
//! `cos / pi`), an unbiased estimate of the proxies' interreflection whose noise falls
//! as `1 / sqrt(samples)`; no ray stops early. A ray leaving a sphere of the receiver's
//! own object is not stopped by the spheres that hold the receiver or lie behind its
//! tangent plane (the self-shadowing rule of the direct light).

use super::Context;
use crate::logsh::{own_sphere_holds, Lobe};
use crate::reference::LobeTerm;
use crate::shade::bounce::{ray_hits_sphere, terrain_hit, SurfaceAlbedos};
use crate::shade::frame::suns_along;
use crate::shade::kernel::above_ground;
use crate::vector::{dot, frame_around};
use std::f64::consts::TAU;

/// What a bounce ray met: the point, its unit normal, its object, its albedo and its
/// specular reflectance.
struct Hit {
    point: [f64; 3],
    normal: [f64; 3],
    object: u32,
    albedo: [f32; 3],
    specular: [f32; 3],
}

/// A small deterministic generator (SplitMix64) for the jitter of the strata.
struct Jitter(u64);

impl Jitter {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

impl Context<'_> {
    /// The bounce light a white diffuse receiver at `p` with unit normal `n` reflects,
    /// `E / pi` (RGB), through up to `bounces` bounces (module doc).
    pub(super) fn bounced(
        &self,
        albedos: &SurfaceAlbedos,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
        bounces: usize,
        seed: u64,
    ) -> [f64; 3] {
        if bounces == 0 {
            return [0.0; 3];
        }
        let side = (self.options.bounce_samples as f64).sqrt().ceil().max(1.0) as usize;
        let (e1, e2) = frame_around(n);
        let mut jitter = Jitter(seed ^ 0xb0b0_cafe);
        let mut sum = [0.0f64; 3];
        for i in 0..side * side {
            let u = ((i % side) as f64 + jitter.next()) / side as f64;
            let v = ((i / side) as f64 + jitter.next()) / side as f64;
            let (radius, phi) = (u.sqrt(), TAU * v);
            let up = (1.0 - u).max(0.0).sqrt();
            let w: [f64; 3] = std::array::from_fn(|k| radius * (phi.cos() * e1[k] + phi.sin() * e2[k]) + up * n[k]);
            let Some(hit) = self.first_hit(albedos, p, n, w, object) else { continue };
            let hit_seed = seed.wrapping_mul(0x2545_f491_4f6c_dd1d).wrapping_add(i as u64 + 1);
            let reflected = self.reflected_by(albedos, &hit, w, bounces - 1, hit_seed);
            (0..3).for_each(|c| sum[c] += reflected[c]);
        }
        sum.map(|s| s / (side * side) as f64)
    }

    /// The radiance `hit`, met along unit `w`, sends back along `-w`: its albedo times
    /// its direct light and its own bounce (`bounces` more), and its specular reflectance
    /// times what arrives along the mirror direction: the light, where nothing is met
    /// (the Sun lamps' disks included), or, with a bounce left, what the surface met there
    /// reflects.
    fn reflected_by(&self, albedos: &SurfaceAlbedos, hit: &Hit, w: [f64; 3], bounces: usize, seed: u64) -> [f64; 3] {
        let direct = self.white_direct(hit.point, hit.normal, hit.object, seed);
        let further = self.bounced(albedos, hit.point, hit.normal, hit.object, bounces, seed);
        let mut out: [f64; 3] = std::array::from_fn(|c| f64::from(hit.albedo[c]) * (direct[c] + further[c]));
        if hit.specular != [0.0; 3] {
            let along = dot(w, hit.normal);
            let mirror: [f64; 3] = std::array::from_fn(|k| w[k] - 2.0 * along * hit.normal[k]);
            let arriving = match self.first_hit(albedos, hit.point, hit.normal, mirror, hit.object) {
                Some(next) if bounces > 0 => self.reflected_by(
                    albedos,
                    &next,
                    mirror,
                    bounces - 1,
                    seed.wrapping_mul(0x9e37_79b9).wrapping_add(7),
                ),
                Some(_) => [0.0; 3],
                None => {
                    let suns = suns_along(&self.frame.suns, mirror);
                    let sky = self.light_along(mirror);
                    std::array::from_fn(|c| sky[c] + f64::from(suns[c]))
                }
            };
            (0..3).for_each(|c| out[c] += f64::from(hit.specular[c]) * arriving[c]);
        }
        out
    }

    /// The direct light a white diffuse surface at `p` reflects (`E / pi`).
    fn white_direct(&self, p: [f64; 3], n: [f64; 3], object: u32, seed: u64) -> [f64; 3] {
        let terms = [LobeTerm { lobe: Lobe::Diffuse, axis: n, scale: [1.0; 3], ggx: None }];
        self.lit(p, n, object, &terms, 4.0 * self.options.tolerance, seed).rgb
    }

    /// The first of the spheres, the ground plane and the height field the ray from `p`
    /// (normal `n`, on `object`) along unit `w` meets.
    fn first_hit(&self, albedos: &SurfaceAlbedos, p: [f64; 3], n: [f64; 3], w: [f64; 3], object: u32) -> Option<Hit> {
        let mut best: Option<(f64, Hit)> = None;
        let mut take = |t: f64, hit: Hit| {
            if t > 0.0 && best.as_ref().is_none_or(|(b, _)| t < *b) {
                best = Some((t, hit));
            }
        };
        for sphere in self.occluders.spheres.iter().filter(|s| s.radius > 0.0) {
            let to: [f64; 3] = std::array::from_fn(|k| sphere.center[k] - p[k]);
            let own = object != 0 && sphere.object == object;
            if own && (own_sphere_holds(p, sphere.center, sphere.radius) || dot(to, n) <= 0.0) {
                continue;
            }
            let Some(t) = ray_hits_sphere(p, w, sphere.center, sphere.radius) else { continue };
            let point: [f64; 3] = std::array::from_fn(|k| p[k] + t * w[k]);
            let normal = std::array::from_fn(|k| (point[k] - sphere.center[k]) / sphere.radius);
            let (albedo, specular) = (albedos.of_object(sphere.object), albedos.specular_of_object(sphere.object));
            take(t, Hit { point, normal, object: sphere.object, albedo, specular });
        }
        if let Some(field) = self.occluders.field {
            let spacing = field.spacing();
            let step = 0.25 * spacing[0].max(spacing[1]).max(1e-6);
            let size = (0..2).map(|a| field.max()[a] - field.min()[a]).fold(0.0, f64::max);
            if let Some((point, t)) = terrain_hit(|x, y| field.height_at(x, y), p, w, step, 4.0 * size) {
                let normal = field.normal_at(point[0], point[1]);
                take(t, Hit { point, normal, object: 0, albedo: albedos.terrain, specular: [0.0; 3] });
            }
        } else if let Some(ground) = self.occluders.ground.filter(|&z| above_ground(p, z) && w[2] < 0.0) {
            let t = (ground - p[2]) / w[2];
            let point = std::array::from_fn(|k| p[k] + t * w[k]);
            take(t, Hit { point, normal: [0.0, 0.0, 1.0], object: 0, albedo: albedos.terrain, specular: [0.0; 3] });
        }
        best.map(|(_, hit)| hit)
    }
}
