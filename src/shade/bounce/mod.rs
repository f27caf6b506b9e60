//! Bounce light: what the terrain (the height field, or the ground plane) and the sphere
//! blockers reflect onto each surface point, added outside the exponential
//! (docs/method/bounce-light.md).
//!
//! The surroundings are shaded as secondary lights at points of their own: the texels of
//! a grid over the terrain and fourteen points around each blocker sphere. Their direct
//! light comes from the executor that shades the frame (the same kernel, the same
//! visibility), times an albedo baked from the frame's own pixels (the Diffuse Color pass,
//! or the material). Each further bounce gathers at those points what the previous one
//! left on them. A receiver then gathers, into an SH vector `U` of [`ORDER`] of incident
//! radiance:
//!
//! - the terrain after NS09 (paper 003, Section 3, Eq. 6-12): along each of
//!   [`AZIMUTHS`] azimuths, the casting set (the samples that rise above all nearer ones)
//!   with each member's radiance held from its blocking angle up to the next one's, in the
//!   NLP basis (Eq. 12), turned into SH by the wedge operator of paper 000 (Eq. 18-23);
//! - each blocker sphere as a cap (paper 000, Section 7: the cap's directions return the
//!   sphere's reflected radiance instead of black) of the radiance its side facing the
//!   receiver has, with the caps of one object scaled by how much of their summed area
//!   the object's union covers (the spheres of a proxy overlap).
//!
//! and irradiance `E(n) = sum_lm A_l U_lm y_lm(n)` with the clamped cosine's
//! `A = (pi, 2 pi / 3, pi / 4, 0, -pi / 24)`. Order 3 (Ramamoorthi and Hanrahan 2001)
//! was 10 % off ray casting over a bowl, where the surroundings fill the lower part of the
//! lobe with a sharp edge; order 5 is within 2 % on its walls and 8 % on its floor, where
//! the march's steps pass the rim's crest (the tests below). A point's bounce is
//! its diffuse albedo times `E / pi`, scaled by [`leak_scale`]. The coarse grid suffices
//! because bounce light is low-frequency; a sphere cap in front of the terrain adds to it
//! rather than hiding it, and a sphere's radiance is read at one point per cap: the
//! approximations of paper 000's Section 7.

use super::frame::{height_field, unit_or_up, ShadeError};
use super::point::SurfacePoint;
pub use super::settings::{BounceSettings, MAX_BOUNCES, MAX_BOUNCE_GRID, MAX_BOUNCE_STRIDE, MIN_BOUNCE_GRID};
use crate::heightfield::HeightField;
use crate::logsh::{cap_log_zh, nlp_slice_of_sine, WedgeOperator, WedgeTurn};
use crate::scene::gbuffer::SurfaceColours;
use crate::scene::{Frame, GBuffer, Material, Scene};
use crate::sh::basis::{clamped_cosine_factor, eval_basis};
use crate::sh::rotation::add_rotated_zonal;
use rayon::prelude::*;
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::f64::consts::PI;

mod gather;
pub use gather::{IndirectParts, SkyWeighting};

/// The SH order of the gathered radiance.
const ORDER: usize = 5;
const COUNT: usize = ORDER * ORDER;
/// Azimuths of the terrain gather.
pub const AZIMUTHS: usize = 16;
/// Ratio of successive steps along an azimuth: each step's footprint is about a fifth of
/// its distance, which the grid's texels cover beyond a few texels.
const STEP_RATIO: f64 = 1.15;
/// What a gather carries per SH coefficient: the radiance in R, G, B, and the occlusion
/// (radiance 1 wherever the surroundings are, times the sky's luminance there once the
/// gather is weighted by a sky, [`SkyWeighting`]), which tells how much of a receiver's
/// light they cover.
const CHANNELS: usize = 4;
/// The occlusion's channel.
const OCCLUSION: usize = 3;
/// The fourteen directions a sphere's secondary points lie along: the axes and the
/// diagonals.
const SPHERE_DIRECTIONS: usize = 14;

/// Most blocker spheres that reflect light, the largest: each is 14 points to shade and a
/// cap to gather at every receiver, and a particle system's thousands of small spheres
/// reflect little (they still shadow).
pub const MAX_SPHERE_LIGHTS: usize = 256;
/// The terrain as a secondary light: a grid of texels over the height field (or over the
/// frame's neighbourhood of the ground plane), each with its surface point, albedo and
/// radiance.
struct TerrainGrid {
    min: [f64; 2],
    max: [f64; 2],
    side: usize,
    /// `None`: the ground plane at this height.
    field: Option<HeightField>,
    ground: f64,
    albedo: Vec<[f32; 3]>,
    radiance: Vec<[f32; 3]>,
    material: u32,
}

impl TerrainGrid {
    fn height(&self, x: f64, y: f64) -> f64 {
        self.field.as_ref().map_or(self.ground, |f| f.height_at(x, y))
    }

    fn texel_position(&self, i: usize) -> [f64; 3] {
        let (c, r) = (i % self.side, i / self.side);
        let last = (self.side - 1) as f64;
        let x = self.min[0] + (self.max[0] - self.min[0]) * c as f64 / last;
        let y = self.min[1] + (self.max[1] - self.min[1]) * r as f64 / last;
        [x, y, self.height(x, y)]
    }

    fn normal_at(&self, x: f64, y: f64) -> [f64; 3] {
        self.field.as_ref().map_or([0.0, 0.0, 1.0], |field| field.normal_at(x, y))
    }

    /// Whether `p` lies on the terrain (to a hundredth of a texel, or f32 rounding).
    fn holds(&self, p: [f64; 3]) -> bool {
        let tolerance = 1e-3 * (1.0 + p[2].abs()) + 0.01 * (self.max[0] - self.min[0]) / self.side as f64;
        (p[2] - self.height(p[0], p[1])).abs() <= tolerance
    }

    /// The texel containing world `(x, y)`, clamped to the grid.
    fn texel_of(&self, x: f64, y: f64) -> usize {
        let last = (self.side - 1) as f64;
        let at = |v: f64, a: usize| {
            (((v - self.min[a]) / (self.max[a] - self.min[a]) * last).round().clamp(0.0, last)) as usize
        };
        at(y, 1) * self.side + at(x, 0)
    }

    /// Bilinear radiance at world `(x, y)`, clamped to the grid's edge.
    fn radiance_at(&self, x: f64, y: f64) -> [f64; 3] {
        let last = (self.side - 1) as f64;
        let u = ((x - self.min[0]) / (self.max[0] - self.min[0]) * last).clamp(0.0, last);
        let v = ((y - self.min[1]) / (self.max[1] - self.min[1]) * last).clamp(0.0, last);
        let (c0, r0) = ((u.floor() as usize).min(self.side - 2), (v.floor() as usize).min(self.side - 2));
        let (fx, fy) = (u - c0 as f64, v - r0 as f64);
        let at = |c: usize, r: usize| self.radiance[r * self.side + c].map(f64::from);
        let (a, b, c, d) = (at(c0, r0), at(c0 + 1, r0), at(c0, r0 + 1), at(c0 + 1, r0 + 1));
        std::array::from_fn(|k| (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy)
    }

    /// The first point where the ray from `p` along unit `d` meets the terrain, and its
    /// distance ([`terrain_hit`], steps of a quarter texel, out to twice the grid).
    fn hit(&self, p: [f64; 3], d: [f64; 3]) -> Option<([f64; 3], f64)> {
        let span = (self.max[0] - self.min[0]).max(self.max[1] - self.min[1]);
        terrain_hit(|x, y| self.height(x, y), p, d, 0.25 * span / (self.side - 1) as f64, 2.0 * span)
    }

    /// Adds the terrain's radiance seen from `p` to `slices` (NLP, per azimuth and colour
    /// channel): NS09's Eq. 12 over the casting set, closed at the horizontal where the
    /// last sample is below it (the flat continuation beyond the grid).
    fn add_slices(&self, p: [f64; 3], slices: &mut [[f64; ORDER]; CHANNELS * AZIMUTHS]) {
        let span = (self.max[0] - self.min[0]).max(self.max[1] - self.min[1]);
        let first = 0.5 * span / (self.side - 1) as f64;
        let far =
            2.0 * span + (0..2).map(|a| (p[a] - self.min[a]).abs().max((p[a] - self.max[a]).abs())).fold(0.0, f64::max);
        let mut below = [0.0; ORDER];
        let mut above = [0.0; ORDER];
        for k in 0..AZIMUTHS {
            let phi = 2.0 * PI * k as f64 / AZIMUTHS as f64;
            let (dy, dx) = phi.sin_cos();
            let (mut sine, mut radiance) = (-1.0f64, [0.0f64; CHANNELS]);
            nlp_slice_of_sine(ORDER, 1.0, sine, &mut below);
            let mut t = first;
            while t < far {
                let (x, y) = (p[0] + t * dx, p[1] + t * dy);
                let rise = self.height(x, y) - p[2];
                let s = rise / (rise * rise + t * t).sqrt();
                if s > sine {
                    let [r, g, b] = self.radiance_at(x, y);
                    radiance = [r, g, b, 1.0];
                    nlp_slice_of_sine(ORDER, 1.0, s, &mut above);
                    add_band(&mut slices[CHANNELS * k..CHANNELS * (k + 1)], radiance, &below, &above);
                    below = above;
                    sine = s;
                }
                t *= STEP_RATIO;
            }
            if sine < 0.0 {
                nlp_slice_of_sine(ORDER, 1.0, 0.0, &mut above);
                add_band(&mut slices[CHANNELS * k..CHANNELS * (k + 1)], radiance, &below, &above);
            }
        }
    }
}

/// The first point where the ray from `p` along unit `d` goes below the surface
/// `height(x, y)`, and its distance, within `far`: steps of `step` near `p`, growing
/// with the distance travelled by a tenth, the crossing then refined by bisection to
/// `step / 4096`. A surface thinner than a step along the ray can be missed.
pub fn terrain_hit(
    height: impl Fn(f64, f64) -> f64,
    p: [f64; 3],
    d: [f64; 3],
    step: f64,
    far: f64,
) -> Option<([f64; 3], f64)> {
    let below = |t: f64| {
        let q: [f64; 3] = std::array::from_fn(|k| p[k] + t * d[k]);
        q[2] < height(q[0], q[1])
    };
    let (mut t, mut before) = (step, 0.0);
    while t < far {
        if below(t) {
            let (mut lo, mut hi) = (before, t);
            for _ in 0..12 {
                let mid = 0.5 * (lo + hi);
                if below(mid) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            return Some((std::array::from_fn(|k| p[k] + hi * d[k]), hi));
        }
        before = t;
        t += step.max(0.1 * t);
    }
    None
}

/// How far along the ray from `p` in unit direction `d` it enters the sphere
/// `(centre, radius)`; `None` where it misses, where the sphere is behind `p`, and where
/// `p` lies inside it.
pub fn ray_hits_sphere(p: [f64; 3], d: [f64; 3], centre: [f64; 3], radius: f64) -> Option<f64> {
    let to: [f64; 3] = std::array::from_fn(|k| centre[k] - p[k]);
    let (along, squared) = (dot(to, d), dot(to, to));
    let miss = squared - along * along - radius * radius;
    (along > 0.0 && miss <= 0.0 && squared > radius * radius).then(|| along - (-miss).sqrt())
}

/// Adds `radiance` times the NLP band between two cumulative integrals (Eq. 12's
/// `u(t_i) (v(w_i) - v(w_{i-1}))`).
fn add_band(slices: &mut [[f64; ORDER]], radiance: [f64; CHANNELS], below: &[f64; ORDER], above: &[f64; ORDER]) {
    for (channel, slice) in slices.iter_mut().enumerate() {
        for l in 0..ORDER {
            slice[l] += radiance[channel] * (above[l] - below[l]);
        }
    }
}

/// One blocker sphere as a secondary light: its radiance at [`SPHERE_DIRECTIONS`] points
/// around it (`None` where the point lies under the terrain).
///
/// A point sends its diffuse albedo times its irradiance over pi, and the sphere's
/// specular reflectance times the mean radiance incident on the whole sphere: a mirror
/// sphere seen from afar reflects every direction of the sphere once, with equal weight
/// per unit of its apparent disk, so its mean radiance towards any receiver is its
/// reflectance times the mean incident radiance (under a parallel beam it scatters the
/// same intensity every way). That mean is the mean irradiance over all normals over pi
/// (`mean_n max(0, n . w) = 1/4`), taken over the fourteen points with Lebedev's weights
/// (exact for polynomials of degree 5 on the sphere). Without it a metal blocker was
/// black to its surroundings: the floor of `glossy.py` (four metal spheres) was 0.029
/// darker on average than Cycles' render with Blender's light paths; with it, 0.004.
struct SphereLight {
    centre: [f64; 3],
    radius: f64,
    object: u32,
    albedo: [f32; 3],
    /// Its object's mean specular reflectance (the Glossy Color pass, or the material's
    /// specular colour).
    specular: [f32; 3],
    radiance: [Option<[f32; 3]>; SPHERE_DIRECTIONS],
    /// How much of the summed area of its object's spheres their union covers.
    overlap: f64,
}

impl SphereLight {
    /// Sets the radiance of the points from their irradiance over pi (`None` where a
    /// point lies under the terrain).
    fn reflect(&mut self, irradiance: [Option<[f32; 3]>; SPHERE_DIRECTIONS]) {
        let (mut mean, mut weights) = ([0.0f64; 3], 0.0);
        for (k, e) in irradiance.iter().enumerate() {
            let Some(e) = e else { continue };
            let w = lebedev_weight(k);
            (0..3).for_each(|c| mean[c] += w * f64::from(e[c]));
            weights += w;
        }
        let mirrored: [f32; 3] =
            std::array::from_fn(|c| if weights > 0.0 { self.specular[c] * (mean[c] / weights) as f32 } else { 0.0 });
        self.radiance = irradiance.map(|e| e.map(|e| std::array::from_fn(|c| self.albedo[c] * e[c] + mirrored[c])));
    }

    /// The radiance of the sphere's side facing `m` (a unit vector from its centre): its
    /// points' radiance weighted by `max(0, m . m_k)^4`.
    fn radiance_towards(&self, m: [f64; 3]) -> [f64; 3] {
        let (mut sum, mut weights) = ([0.0; 3], 0.0);
        for (k, radiance) in self.radiance.iter().enumerate() {
            let Some(radiance) = radiance else { continue };
            let w = dot(m, sphere_direction(k)).max(0.0).powi(4);
            for c in 0..3 {
                sum[c] += w * f64::from(radiance[c]);
            }
            weights += w;
        }
        if weights > 0.0 {
            sum.map(|s| s / weights)
        } else {
            [0.0; 3]
        }
    }
}

/// The weight of [`sphere_direction`]`(k)` in Lebedev's 14-point rule on the sphere:
/// 1/15 for the axes, 3/40 for the diagonals (they sum to 1).
fn lebedev_weight(k: usize) -> f64 {
    if k < 6 {
        1.0 / 15.0
    } else {
        3.0 / 40.0
    }
}

fn sphere_direction(k: usize) -> [f64; 3] {
    const AXES: [[f64; 3]; 6] =
        [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    if k < 6 {
        AXES[k]
    } else {
        let s = 1.0 / 3f64.sqrt();
        let j = k - 6;
        [if j & 1 == 0 { s } else { -s }, if j & 2 == 0 { s } else { -s }, if j & 4 == 0 { s } else { -s }]
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// A frame's surroundings, ready to be shaded: the secondary points as a G-buffer
/// ([`Self::points`]), to go through the executor's direct shading before
/// [`Self::lit`].
pub struct SurroundingsPlan {
    points: Frame,
    /// What the spheres' points are shaded with ([`Self::points_scene`]).
    sphere_points: PointMaterial,
    terrain: Option<TerrainGrid>,
    spheres: Vec<SphereLight>,
    bounces: usize,
}

/// Calls its argument with a frame's G-buffer rows, band after band in order, every row
/// once ([`SurroundingsPlan::surveyed`]).
pub type EachBand<'a> = dyn FnMut(&mut dyn FnMut(&GBuffer)) -> Result<(), ShadeError> + 'a;

/// A frame's surroundings with their radiance after all but the last bounce.
pub struct Surroundings {
    terrain: Option<TerrainGrid>,
    spheres: Vec<SphereLight>,
    turn: WedgeTurn<f64>,
    /// The sky the gather's covered share is weighted by.
    sky: Option<SkyWeighting>,
}

/// Whether pixel `i` of `g` is a surface the surroundings summarise: a material, not
/// water.
fn is_surface(scene: &Scene, g: &GBuffer, i: usize) -> bool {
    matches!(scene.materials.get(&g.material[i]), Some(m) if !matches!(m, Material::Water { .. }))
}

/// What a pixel reflects diffusely: its Diffuse Color pass, or its material's albedo;
/// black for water and the background.
pub fn diffuse_albedo(scene: &Scene, gbuffer: &GBuffer, i: usize) -> [f32; 3] {
    surface_colours(scene, gbuffer, i).0
}

/// What a pixel reflects, diffusely and specularly: its Diffuse Color and Glossy Color
/// passes, or its material's albedo and specular colour; black for water and the
/// background.
fn surface_colours(scene: &Scene, gbuffer: &GBuffer, i: usize) -> ([f32; 3], [f32; 3]) {
    match scene.materials.get(&gbuffer.material[i]) {
        None | Some(Material::Water { .. }) => ([0.0; 3], [0.0; 3]),
        Some(material) => gbuffer.colours_at(i).unwrap_or_else(|| material.pass_colours()),
    }
}

/// The albedos the surroundings reflect with, baked from the frame's own pixels
/// ([`diffuse_albedo`]): the mean over the pixels of each object (blocker spheres of an
/// object take its mean), over the terrain's pixels, and over every surface pixel (what
/// a blocker of no object, or of an object no pixel shows, takes; and the terrain where
/// none of its pixels is seen). Each object's mean specular reflectance beside them:
/// a blocker no pixel shows reflects no mirror image.
pub struct SurfaceAlbedos {
    pub by_object: BTreeMap<u32, [f32; 3]>,
    pub specular_by_object: BTreeMap<u32, [f32; 3]>,
    pub terrain: [f32; 3],
    pub frame: [f32; 3],
}

/// A sum of colours and how many were added.
type ColourSum = ([f64; 3], usize);

/// The sums behind [`SurfaceAlbedos`], added pixel by pixel in the frame's order.
#[derive(Default)]
struct AlbedoSums {
    /// Per object, the diffuse and the specular sums.
    by_object: BTreeMap<u32, [ColourSum; 2]>,
    terrain: ColourSum,
    all: ColourSum,
}

impl AlbedoSums {
    /// Adds surface pixel `i` of `g` (not water, not the background).
    fn add(&mut self, scene: &Scene, g: &GBuffer, i: usize, on_terrain: bool) {
        let (albedo, specular) = surface_colours(scene, g, i);
        let add = |sum: &mut ColourSum, colour: [f32; 3]| {
            (0..3).for_each(|c| sum.0[c] += f64::from(colour[c]));
            sum.1 += 1;
        };
        add(&mut self.all, albedo);
        if on_terrain {
            add(&mut self.terrain, albedo);
        }
        if g.object_at(i) != 0 {
            let [diffuse_sum, specular_sum] = self.by_object.entry(g.object_at(i)).or_default();
            add(diffuse_sum, albedo);
            add(specular_sum, specular);
        }
    }

    fn means(self) -> SurfaceAlbedos {
        let mean = |(sum, n): ColourSum| (n > 0).then(|| sum.map(|v| (v / n as f64) as f32));
        let frame = mean(self.all).unwrap_or([0.0; 3]);
        let by_object = |part: usize| {
            self.by_object.iter().filter_map(|(&object, sums)| Some((object, mean(sums[part])?))).collect()
        };
        SurfaceAlbedos {
            by_object: by_object(0),
            specular_by_object: by_object(1),
            terrain: mean(self.terrain).unwrap_or(frame),
            frame,
        }
    }
}

impl SurfaceAlbedos {
    /// The albedos of `frame`'s pixels; `on_terrain(i)` tells whether pixel `i` lies on
    /// the terrain.
    pub fn of(scene: &Scene, frame: &Frame, on_terrain: impl Fn(usize) -> bool) -> Self {
        let g = &frame.gbuffer;
        let mut sums = AlbedoSums::default();
        for i in 0..g.material.len() {
            if is_surface(scene, g, i) {
                sums.add(scene, g, i, on_terrain(i));
            }
        }
        sums.means()
    }

    /// The albedo of the spheres of `object`.
    pub fn of_object(&self, object: u32) -> [f32; 3] {
        (object != 0).then(|| self.by_object.get(&object)).flatten().copied().unwrap_or(self.frame)
    }

    /// The specular reflectance of the spheres of `object` (black where no pixel shows
    /// it).
    pub fn specular_of_object(&self, object: u32) -> [f32; 3] {
        (object != 0).then(|| self.specular_by_object.get(&object)).flatten().copied().unwrap_or([0.0; 3])
    }
}

impl SurroundingsPlan {
    /// The secondary points of `frame`, or `None` where nothing bounces: no bounce asked,
    /// or neither terrain (height field or ground plane) nor blockers.
    pub fn new(scene: &Scene, frame: &Frame, settings: &BounceSettings) -> Result<Option<Self>, ShadeError> {
        Self::surveyed(scene, frame, settings, &mut |visit| {
            visit(&frame.gbuffer);
            Ok(())
        })
    }

    /// [`Self::new`] for a frame read in bands: `each_band(visit)` calls `visit` with the
    /// G-buffer's bands of rows in order, every row once (`frame` is any of them, which
    /// lends the frame's camera, light and blockers). The surroundings are the same as
    /// those of the whole frame, which they summarise: their bounds, albedos and
    /// materials are sums and counts over its pixels in order.
    pub fn surveyed(
        scene: &Scene,
        frame: &Frame,
        settings: &BounceSettings,
        each_band: &mut EachBand,
    ) -> Result<Option<Self>, ShadeError> {
        if settings.bounces == 0 {
            return Ok(None);
        }
        let field = height_field(scene, frame)?;
        // The first pass: the first surface pixel's material, and where a ground plane is
        // the terrain, the surface pixels' places over it.
        let ground_grid = field.is_none() && frame.ground.is_some();
        let mut fallback = None;
        let mut places: [Vec<f32>; 2] = [Vec::new(), Vec::new()];
        each_band(&mut |g| {
            for i in (0..g.material.len()).filter(|&i| is_surface(scene, g, i)) {
                fallback.get_or_insert(g.material[i]);
                if ground_grid {
                    (0..2).for_each(|a| places[a].push(g.position[i][a]));
                }
            }
        })?;
        let Some(fallback_material) = fallback else { return Ok(None) };
        let terrain = match field {
            Some(field) => Some((field.min(), field.max(), Some(field), 0.0)),
            None => frame.ground.map(|ground| {
                let (min, max) = neighbourhood(places, &frame.blockers);
                (min, max, None, ground)
            }),
        };
        let side = settings.grid.max(2);
        let terrain = terrain.map(|(min, max, field, ground)| TerrainGrid {
            min,
            max,
            side,
            field,
            ground,
            albedo: Vec::new(),
            radiance: vec![[0.0; 3]; side * side],
            material: fallback_material,
        });
        // The second pass: the albedos and reflectances, and the terrain's material.
        let mut albedo_sums = AlbedoSums::default();
        let mut texel_sums = vec![([0.0f64; 3], 0usize); side * side];
        let mut grid_materials = BTreeMap::<u32, usize>::new();
        each_band(&mut |g| {
            for i in (0..g.material.len()).filter(|&i| is_surface(scene, g, i)) {
                let on_terrain = terrain.as_ref().is_some_and(|grid| grid.holds(g.position[i].map(f64::from)));
                albedo_sums.add(scene, g, i, on_terrain);
                if let (true, Some(grid)) = (on_terrain, &terrain) {
                    let p = g.position[i];
                    let texel = &mut texel_sums[grid.texel_of(f64::from(p[0]), f64::from(p[1]))];
                    let a = diffuse_albedo(scene, g, i);
                    (0..3).for_each(|c| texel.0[c] += f64::from(a[c]));
                    texel.1 += 1;
                    *grid_materials.entry(g.material[i]).or_default() += 1;
                }
            }
        })?;
        let albedos = albedo_sums.means();
        let terrain = terrain.map(|mut grid| {
            grid.material = grid_materials.into_iter().max_by_key(|&(_, n)| n).map_or(fallback_material, |(m, _)| m);
            grid.albedo = texel_sums
                .iter()
                .map(|&(s, n)| if n > 0 { s.map(|v| (v / n as f64) as f32) } else { albedos.terrain })
                .collect();
            grid
        });

        let mut spheres =
            largest_spheres(frame, |object| (albedos.of_object(object), albedos.specular_of_object(object)));
        set_overlaps(&mut spheres);
        if terrain.is_none() && spheres.is_empty() {
            return Ok(None);
        }

        let sphere_points = PointMaterial::of(scene);
        let points = secondary_points(scene, frame, terrain.as_ref(), &spheres, sphere_points.index);
        Ok(Some(Self { points, sphere_points, terrain, spheres, bounces: settings.bounces }))
    }

    /// The secondary points as a frame to shade with direct light, with
    /// [`Self::points_scene`].
    pub fn points(&self) -> &Frame {
        &self.points
    }

    /// The scene to shade [`Self::points`] with: `scene` itself, or, where none of its
    /// materials can stand for the spheres' points ([`PointMaterial`]), a copy with a
    /// white diffuse material added.
    pub fn points_scene<'a>(&self, scene: &'a Scene) -> Cow<'a, Scene> {
        if !self.sphere_points.added {
            return Cow::Borrowed(scene);
        }
        let mut with_white = scene.clone();
        with_white.materials.insert(self.sphere_points.index, Material::Diffuse { albedo: [1.0; 3] });
        Cow::Owned(with_white)
    }

    /// The surroundings lit: `direct` is the diffuse pass of [`Self::points`] shaded
    /// with [`Self::points_scene`] (a texel's albedo, a sphere's point the albedo of
    /// [`PointMaterial`], times direct irradiance over pi), `visibility` their visibility
    /// pass; each bounce after the first gathers at the points what the one before left
    /// on them. `sky_luminance`: the SH coefficients of the luminance of the light the
    /// visibility pass weighs by ([`SkyWeighting`]).
    pub fn lit(self, scene: &Scene, direct: &[[f32; 3]], visibility: &[f32], sky_luminance: &[f64]) -> Surroundings {
        let Self { points, sphere_points, terrain, spheres, bounces } = self;
        let turn = WedgeOperator::new(ORDER, AZIMUTHS).turn();
        let mut surroundings = Surroundings { terrain, spheres, turn, sky: SkyWeighting::new(sky_luminance) };
        let side = surroundings.terrain.as_ref().map_or(0, |t| t.side);
        // The spheres' points as irradiance over pi: their shading's albedo divided out.
        let direct: Vec<[f32; 3]> = direct
            .iter()
            .enumerate()
            .map(|(i, d)| if i < side * side { *d } else { std::array::from_fn(|c| d[c] / sphere_points.albedo[c]) })
            .collect();
        surroundings.set_light(&direct);
        let g = &points.gbuffer;
        let count = surroundings.point_count();
        // The texels gather on every other row and column, the rest interpolate between
        // them: bounce light varies over several texels.
        let on_lattice = |c: usize| c % 2 == 0 || c + 1 == side;
        for _ in 1..bounces {
            let mut gathered: Vec<Option<[f64; 3]>> = (0..count)
                .into_par_iter()
                .map(|i| {
                    if i < side * side && !(on_lattice(i % side) && on_lattice(i / side)) {
                        return None;
                    }
                    let (p, n) = (g.position[i].map(f64::from), unit_or_up(g.normal[i]));
                    let [terrain, spheres] = surroundings.irradiance(p, n, g.object_at(i), Some(visibility[i]));
                    Some(std::array::from_fn(|c| terrain[c] + spheres[c]))
                })
                .collect();
            for i in 0..side * side {
                if gathered[i].is_none() {
                    let (c, r) = (i % side, i / side);
                    let span = |v: usize| if on_lattice(v) { [v, v] } else { [v - 1, v + 1] };
                    let corners = [span(c), span(r)];
                    let mut e = [0.0; 3];
                    for row in corners[1] {
                        for column in corners[0] {
                            let corner = gathered[row * side + column].expect("a lattice texel");
                            (0..3).for_each(|k| e[k] += 0.25 * corner[k]);
                        }
                    }
                    gathered[i] = Some(e);
                }
            }
            let light: Vec<[f32; 3]> = (0..count)
                .map(|i| {
                    // A texel reflects through its albedo; a sphere's point is white.
                    let albedo = if i < side * side { diffuse_albedo(scene, g, i) } else { [1.0; 3] };
                    let e = gathered[i].unwrap_or([0.0; 3]);
                    std::array::from_fn(|c| direct[i][c] + albedo[c] * (e[c] / PI) as f32)
                })
                .collect();
            surroundings.set_light(&light);
        }
        surroundings
    }
}

/// The material the spheres' secondary points are shaded with, and the albedo their
/// diffuse pass then carries, which [`SurroundingsPlan::lit`] divides out to leave their
/// irradiance over pi ([`SphereLight`] applies the sphere's own albedo and reflectance).
/// It is one of the scene's materials where one has an albedo of at least
/// [`MIN_POINT_ALBEDO`] in every channel, so that the points are shaded with the frame's
/// own kernel (built once per sequence, `crate::shade::plan`); otherwise a white diffuse
/// material of a free index, added to a copy of the scene.
#[derive(Clone, Copy, Debug)]
struct PointMaterial {
    index: u32,
    albedo: [f32; 3],
    added: bool,
}

/// The least albedo, per channel, of a material the spheres' points are shaded with, so
/// that what the kernel forms with it stays far from f32's underflow, which the division
/// that undoes it would expose.
const MIN_POINT_ALBEDO: f32 = 0.01;

impl PointMaterial {
    fn of(scene: &Scene) -> Self {
        let least = |a: &[f32; 3]| a.iter().copied().fold(f32::INFINITY, f32::min);
        // Water's diffuse colour is black, so it never qualifies.
        let brightest = scene
            .materials
            .iter()
            .map(|(&index, m)| (index, m.pass_colours().0))
            .filter(|(_, a)| least(a) >= MIN_POINT_ALBEDO)
            .max_by(|(_, a), (_, b)| least(a).total_cmp(&least(b)));
        match brightest {
            // With colour passes the kernel shades the table white and the points' Diffuse
            // Color, white, tints it.
            Some((index, albedo)) => {
                Self { index, albedo: if scene.colour_passes() { [1.0; 3] } else { albedo }, added: false }
            }
            None => {
                let index = (1..=u32::MAX).find(|m| !scene.materials.contains_key(m)).expect("a free material index");
                Self { index, albedo: [1.0; 3], added: true }
            }
        }
    }
}

/// The largest blockers (at most [`MAX_SPHERE_LIGHTS`]) as lights, each with the diffuse
/// albedo and specular reflectance `surface` gives its object.
fn largest_spheres(frame: &Frame, surface: impl Fn(u32) -> ([f32; 3], [f32; 3])) -> Vec<SphereLight> {
    let mut largest: Vec<&crate::scene::Sphere> = frame.blockers.iter().filter(|s| s.radius > 0.0).collect();
    largest.sort_by(|a, b| b.radius.total_cmp(&a.radius));
    largest.truncate(MAX_SPHERE_LIGHTS);
    largest
        .into_iter()
        .map(|sphere| {
            let (albedo, specular) = surface(sphere.object);
            SphereLight {
                centre: sphere.center,
                radius: sphere.radius,
                object: sphere.object,
                albedo,
                specular,
                radiance: [None; SPHERE_DIRECTIONS],
                overlap: 1.0,
            }
        })
        .collect()
}

/// The secondary points of `frame`'s surroundings as a frame of their own, packed side
/// by side in a G-buffer: the terrain grid's texels, then each sphere's directions, just
/// above its surface, of the material `sphere_material` (their Diffuse Color white).
fn secondary_points(
    scene: &Scene,
    frame: &Frame,
    terrain: Option<&TerrainGrid>,
    spheres: &[SphereLight],
    sphere_material: u32,
) -> Frame {
    let mut position = Vec::new();
    let mut normal = Vec::new();
    let mut material = Vec::new();
    let mut object = Vec::new();
    let mut albedo = Vec::new();
    if let Some(grid) = terrain {
        for i in 0..grid.side * grid.side {
            let p = grid.texel_position(i);
            position.push(p.map(|v| v as f32));
            normal.push(grid.normal_at(p[0], p[1]).map(|v| v as f32));
            material.push(grid.material);
            object.push(0);
            albedo.push(grid.albedo[i]);
        }
    }
    for sphere in spheres {
        for k in 0..SPHERE_DIRECTIONS {
            let m = sphere_direction(k);
            let lift = sphere.radius * (1.0 + 1e-3);
            let p: [f64; 3] = std::array::from_fn(|a| sphere.centre[a] + lift * m[a]);
            position.push(p.map(|v| v as f32));
            normal.push(m.map(|v| v as f32));
            material.push(sphere_material);
            object.push(sphere.object);
            albedo.push([1.0; 3]);
        }
    }
    let count = position.len();
    let width = (count as f64).sqrt().ceil() as usize;
    let height = count.div_ceil(width);
    let padded = width * height;
    position.resize(padded, [0.0; 3]);
    normal.resize(padded, [0.0, 0.0, 1.0]);
    material.resize(padded, 0);
    object.resize(padded, 0);
    albedo.resize(padded, [0.0; 3]);
    let colours = scene.colour_passes().then(|| SurfaceColours { diffuse: albedo, glossy: vec![[0.0; 3]; padded] });
    let gbuffer = GBuffer {
        file: frame.gbuffer.file.with_extension("surroundings"),
        width,
        height,
        position,
        normal,
        uv: None,
        material,
        object: Some(object),
        colours,
        first_row: 0,
    };
    Frame {
        number: frame.number,
        gbuffer,
        reflection: None,
        camera: frame.camera.clone(),
        blockers: frame.blockers.clone(),
        // The surroundings' points lie on the proxies, not on the meshes the maps hold.
        sun_shadows: Vec::new(),
        height_map: frame.height_map.clone(),
        light: frame.light.clone(),
        light_file_crc: frame.light_file_crc,
        suns: frame.suns.clone(),
        points: frame.points.clone(),
        ground: frame.ground,
        supersample: 1,
    }
}

/// The rectangle of the ground plane the grid covers: the middle 96 % of the frame's
/// surface points along each axis (a plane seen out to the horizon would stretch the
/// grid over kilometres) and the blockers, widened by half its size on each side.
fn neighbourhood(places: [Vec<f32>; 2], blockers: &[crate::scene::Sphere]) -> ([f64; 2], [f64; 2]) {
    let mut min = [f64::INFINITY; 2];
    let mut max = [f64::NEG_INFINITY; 2];
    for (a, values) in places.into_iter().enumerate() {
        let mut values: Vec<f32> = values.into_iter().filter(|v| v.is_finite()).collect();
        if values.is_empty() {
            continue;
        }
        let last = values.len() - 1;
        let (low, high) = (last / 50, last - last / 50);
        min[a] = f64::from(*values.select_nth_unstable_by(low, f32::total_cmp).1);
        max[a] = f64::from(*values.select_nth_unstable_by(high, f32::total_cmp).1);
    }
    for sphere in blockers {
        for a in 0..2 {
            min[a] = min[a].min(sphere.center[a] - sphere.radius);
            max[a] = max[a].max(sphere.center[a] + sphere.radius);
        }
    }
    if !(0..2).all(|a| min[a].is_finite() && max[a].is_finite()) {
        return ([-1.0; 2], [1.0; 2]);
    }
    let size = (0..2).map(|a| max[a] - min[a]).fold(1e-3, f64::max);
    (min.map(|v| v - 0.5 * size), max.map(|v| v + 0.5 * size))
}

/// Each sphere's [`SphereLight::overlap`]: per object, the area of the union of its
/// spheres' silhouettes over the sum of their areas, averaged over the three axes (each
/// rasterised on a 64 x 64 grid); 1 for spheres of no object.
fn set_overlaps(spheres: &mut [SphereLight]) {
    const CELLS: usize = 64;
    let mut by_object = BTreeMap::<u32, Vec<usize>>::new();
    for (i, s) in spheres.iter().enumerate().filter(|(_, s)| s.object != 0) {
        by_object.entry(s.object).or_default().push(i);
    }
    for members in by_object.values().filter(|m| m.len() > 1) {
        let mut ratios = 0.0;
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let lo = |a: usize| {
                members.iter().map(|&i| spheres[i].centre[a] - spheres[i].radius).fold(f64::INFINITY, f64::min)
            };
            let hi = |a: usize| {
                members.iter().map(|&i| spheres[i].centre[a] + spheres[i].radius).fold(f64::NEG_INFINITY, f64::max)
            };
            let (u0, v0) = (lo(u), lo(v));
            let cell = (hi(u) - u0).max(hi(v) - v0).max(1e-12) / CELLS as f64;
            let mut covered = vec![false; CELLS * CELLS];
            let mut summed = 0usize;
            for &i in members {
                let s = &spheres[i];
                for r in 0..CELLS {
                    for c in 0..CELLS {
                        let x = u0 + (c as f64 + 0.5) * cell - s.centre[u];
                        let y = v0 + (r as f64 + 0.5) * cell - s.centre[v];
                        if x * x + y * y <= s.radius * s.radius {
                            covered[r * CELLS + c] = true;
                            summed += 1;
                        }
                    }
                }
            }
            let union = covered.iter().filter(|&&c| c).count();
            ratios += if summed > 0 { union as f64 / summed as f64 } else { 1.0 };
        }
        for &i in members {
            spheres[i].overlap = ratios / 3.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The covered share the leak scale reads: under a constant sky, the cosine-weighted
    /// share (as before the weighting); under a sky four times as bright overhead as at
    /// the horizon, a cap low on the horizon covers less of the light than of the lobe,
    /// as a quadrature of `occlusion l cos` over `l cos` finds, within 0.001.
    #[test]
    fn the_covered_share_is_weighted_by_the_sky() {
        let quadrature = crate::sh::quadrature::SphereQuadrature::gauss(48);
        let project = |f: &dyn Fn([f64; 3]) -> f64| quadrature.project::<f64>(ORDER, f);
        // A cap of 25 degrees, its centre 12 degrees above the horizon, as the gather's
        // occlusion channel holds it.
        let mut cap = [0.0f64; ORDER];
        cap_log_zh(ORDER, 1.0, 25f64.to_radians(), &mut cap);
        let mut occlusion = [0.0f64; COUNT];
        let elevation = 12f64.to_radians();
        add_rotated_zonal(ORDER, &cap, 1.0, [elevation.cos(), 0.0, elevation.sin()], &mut occlusion);
        let n = [0.0, 0.0, 1.0];
        let mut y = [0.0f64; COUNT];
        eval_basis(ORDER, n, &mut y);
        let cosine_share = |sky: Option<&SkyWeighting>| {
            let weighted = sky.map_or(occlusion, |sky| sky.weigh(&occlusion));
            let mut incident = [[0.0f64; COUNT]; CHANNELS];
            incident[OCCLUSION] = weighted;
            let e = gather::convolved_with(&incident, &y, clamped_cosine_factor);
            e[OCCLUSION] / sky.map_or(PI, |sky| sky.open(&y))
        };
        let unweighted = cosine_share(None);
        let constant = SkyWeighting::new(&project(&|_| 0.7)).expect("a lit sky");
        assert!(
            (cosine_share(Some(&constant)) - unweighted).abs() < 1e-9,
            "constant sky: {} against {unweighted}",
            cosine_share(Some(&constant))
        );

        let luminance = |d: [f64; 3]| 1.0 + 3.0 * d[2] * d[2];
        let graded = SkyWeighting::new(&project(&luminance)).expect("a lit sky");
        let weighted = cosine_share(Some(&graded));
        let lit = |d: [f64; 3]| luminance(d) * d[2].max(0.0);
        let covered = quadrature.integrate(|d| lit(d) * crate::sh::basis::eval_expansion(ORDER, &occlusion, d));
        let expected = covered / quadrature.integrate(lit);
        println!("unweighted {unweighted:.4}, weighted {weighted:.4}, quadrature {expected:.4}");
        assert!(weighted < 0.8 * unweighted, "the dim horizon's share: {weighted} against {unweighted}");
        assert!((weighted - expected).abs() < 0.001, "{weighted} against {expected}");
        assert!(SkyWeighting::new(&[0.0; 16]).is_none(), "a black sky weighs nothing");
    }

    /// A flat terrain of uniform radiance `radiance`, as a [`Surroundings`].
    fn flat(radiance: f32, height: f64) -> Surroundings {
        let side = 16;
        let terrain = TerrainGrid {
            min: [-10.0, -10.0],
            max: [10.0, 10.0],
            side,
            field: None,
            ground: height,
            albedo: vec![[1.0; 3]; side * side],
            radiance: vec![[radiance; 3]; side * side],
            material: 1,
        };
        Surroundings {
            terrain: Some(terrain),
            spheres: Vec::new(),
            turn: WedgeOperator::new(ORDER, AZIMUTHS).turn(),
            sky: None,
        }
    }

    /// A bowl of uniform radiance 1 around receivers on its floor and walls: the gathered
    /// irradiance against `pi` times the cosine-weighted fraction of rays that meet the
    /// bowl, cast exactly ([`terrain_hit`], 4096 stratified rays). `-- --nocapture`
    /// prints the figures.
    #[test]
    fn the_gather_over_a_bowl_matches_ray_casting() {
        let side = 65;
        let bowl = |x: f64, y: f64| 0.1 * (x * x + y * y).min(60.0);
        let heights: Vec<f32> = (0..side * side)
            .map(|i| {
                let (c, r) = ((i % side) as f64, (i / side) as f64);
                bowl(-8.0 + 16.0 * c / 64.0, -8.0 + 16.0 * r / 64.0) as f32
            })
            .collect();
        let field = HeightField::new(heights, side, side, [-8.0, -8.0], [8.0, 8.0]).unwrap();
        let grid_side = 64;
        let terrain = TerrainGrid {
            min: [-8.0, -8.0],
            max: [8.0, 8.0],
            side: grid_side,
            field: Some(field.clone()),
            ground: 0.0,
            albedo: vec![[1.0; 3]; grid_side * grid_side],
            radiance: vec![[1.0; 3]; grid_side * grid_side],
            material: 1,
        };
        let surroundings = Surroundings {
            terrain: Some(terrain),
            spheres: Vec::new(),
            turn: WedgeOperator::new(ORDER, AZIMUTHS).turn(),
            sky: None,
        };
        for (x, y) in [(0.0, 0.0), (2.0, 1.0), (4.0, 0.0), (6.0, -2.0)] {
            let p = [x, y, field.height_at(x, y)];
            let (dx, dy) = (0.2 * x, 0.2 * y);
            let length = (dx * dx + dy * dy + 1.0f64).sqrt();
            let n = [-dx / length, -dy / length, 1.0 / length];
            let [gathered, _] = surroundings.irradiance(p, n, 0, None);
            let (e1, e2) = crate::vector::frame_around(n);
            let strata = 64;
            let mut hits = 0usize;
            for i in 0..strata * strata {
                let u = ((i % strata) as f64 + 0.5) / strata as f64;
                let v = ((i / strata) as f64 + 0.5) / strata as f64;
                let (radius, phi) = (u.sqrt(), 2.0 * PI * v);
                let w: [f64; 3] =
                    std::array::from_fn(|k| radius * (phi.cos() * e1[k] + phi.sin() * e2[k]) + (1.0 - u).sqrt() * n[k]);
                let lifted: [f64; 3] = std::array::from_fn(|k| p[k] + 1e-6 * n[k]);
                hits += usize::from(terrain_hit(|x, y| field.height_at(x, y), lifted, w, 0.01, 64.0).is_some());
            }
            let exact = PI * hits as f64 / (strata * strata) as f64;
            println!("bowl at ({x}, {y}): gathered {:.4}, ray cast {exact:.4}", gathered[0]);
            // Measured: 8 % low on the floor (the march's steps pass the rim's crest), 2 %
            // or better on the walls.
            assert!((gathered[0] - exact).abs() <= 0.1 * exact, "bowl at ({x}, {y}): {} against {exact}", gathered[0]);
        }
    }

    /// A mirror sphere under a light of radiance `L w_z^4` from direction `w` (no
    /// ground): by Funk and Hecke, a point of normal `m` has irradiance over pi
    /// `L (1/5 + (1/4)(4/7) P_2(m_z) - (1/24)(8/35) P_4(m_z))` (the clamped cosine's
    /// factors over pi on the light's Legendre parts), and the mean incident radiance is
    /// `L / 5`. Lebedev's rule is exact for it where equal weights are not (0.2063 L). The
    /// sphere sends its specular reflectance times that mean to every side, and its
    /// diffuse albedo times its side's own irradiance.
    #[test]
    fn a_mirror_sphere_sends_its_reflectance_times_the_mean_incident_radiance() {
        let light = 0.8f64;
        let (albedo, specular) = (0.25f32, 0.9f32);
        let legendre = |z: f64| ((3.0 * z * z - 1.0) / 2.0, (35.0 * z.powi(4) - 30.0 * z * z + 3.0) / 8.0);
        let side = |k: usize| {
            let (p2, p4) = legendre(sphere_direction(k)[2]);
            light * (0.2 + 0.25 * (4.0 / 7.0) * p2 - (1.0 / 24.0) * (8.0 / 35.0) * p4)
        };
        let mut sphere = SphereLight {
            centre: [0.0, 0.0, 1.0],
            radius: 1.0,
            object: 1,
            albedo: [albedo; 3],
            specular: [specular; 3],
            radiance: [None; SPHERE_DIRECTIONS],
            overlap: 1.0,
        };
        sphere.reflect(std::array::from_fn(|k| Some([side(k) as f32; 3])));
        for k in 0..SPHERE_DIRECTIONS {
            let expected = f64::from(albedo) * side(k) + f64::from(specular) * light / 5.0;
            let got = f64::from(sphere.radiance[k].expect("every point lit")[0]);
            assert!((got - expected).abs() < 1e-6, "point {k}: {got} against {expected}");
        }
    }

    /// A broad Phong lobe over a lit plane reads the cosine lobe about its normal: at
    /// `s = 0` exactly `E / pi`, which for a receiver leaning `beta` is `L (1 - cos beta) /
    /// 2`; and a receiver facing up, which sees none of the plane, gets at most a fifth of
    /// what the mirror blur alone read at `s = 0.26` (half the plane's radiance, from
    /// below its tangent plane).
    #[test]
    fn a_broad_glossy_lobe_reads_no_light_from_below_its_tangent_plane() {
        let radiance = 0.8;
        let surroundings = flat(radiance as f32, 0.0);
        let receiver = |n: [f64; 3], exponent: f64| {
            let position = [0.3, -0.2, 1.0];
            let view_origin = [0.3, -4.0, 3.0];
            let mirror = crate::shade::point::reflect_view(view_origin, position, n);
            let point = SurfacePoint { position, normal: n, view_origin, material: 1, object: 0 };
            let receiver = gather::Receiver {
                point,
                albedo: [0.0; 3],
                specular: [1.0; 3],
                exponent: Some(exponent),
                mirror,
                transmitted: None,
                visibility: None,
            };
            let incident = surroundings.incident(position, n, 0);
            f64::from(receiver.reflected(&incident, &surroundings)[0][0])
        };
        let facing_up = receiver([0.0, 0.0, 1.0], 0.26);
        assert!(facing_up <= 0.1 * radiance, "facing up: {facing_up}, the blur alone reads about {}", 0.5 * radiance);
        for degrees in [0.0f64, 60.0, 120.0] {
            let beta = degrees.to_radians();
            let exact = radiance * (1.0 - beta.cos()) / 2.0;
            let got = receiver([beta.sin(), 0.0, beta.cos()], 0.0);
            assert!((got - exact).abs() <= 0.03 * radiance, "{degrees} deg: {got} against {exact}");
        }
    }

    /// Over an infinite plane of uniform radiance `L`, a receiver whose normal leans
    /// `beta` from the zenith sees the plane over `(1 - cos beta) / 2` of its cosine
    /// lobe: `E = pi L (1 - cos beta) / 2` (the closed form of a tilted plate over a
    /// Lambertian ground), to the truncated cosine's own error, a few percent.
    #[test]
    fn a_tilted_receiver_over_a_lit_plane_gets_its_closed_form() {
        let radiance = 0.8;
        let surroundings = flat(radiance as f32, 0.0);
        for degrees in [0.0f64, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0] {
            let beta = degrees.to_radians();
            let n = [beta.sin(), 0.0, beta.cos()];
            let [terrain, _] = surroundings.irradiance([0.3, -0.2, 1.0], n, 0, None);
            let exact = PI * radiance * (1.0 - beta.cos()) / 2.0;
            let tolerance = 0.03 * PI * radiance + 0.02 * exact;
            assert!((terrain[0] - exact).abs() <= tolerance, "{degrees} deg: {} against {exact}", terrain[0]);
        }
    }
}
