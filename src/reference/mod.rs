//! Ground-truth reference renderer (docs/design.md, "Verifying", level 2): exact visibility
//! against the same spheres and height field the fast path uses, and the integral of
//! light x visibility x BRDF over the sphere in f64, with a convergence check per pixel.
//!
//! # What a pixel is
//!
//! The materials of docs/design.md, "Scene format v1", with the same frame walk as
//! [`crate::shade::cpu::shade_plan`]: `diffuse` and `heightfield` are `albedo * integral L V
//! max(n.w, 0)/pi`; `phong` adds `specular * integral L V f(w)`, where `f` is the glossy
//! lobe of the kernel's `--glossy` ([`ReferenceOptions::glossy`]):
//!
//! - `ggx` (the default): GGX's BRDF of width `alpha = sqrt(1 / (2 r + 1))` with the
//!   Fresnel term ([`crate::shade::glossy::Fresnel`]), `F D G2 / (4 n.v)` per unit
//!   radiance ([`crate::shade::glossy::ggx_lit`]), scaled at each `n.v` by the kernel's lamp table
//!   ([`crate::shade::glossy::lamp_scale_table`]) so that it integrates to the albedo the
//!   kernel's environment term is scaled by (GGX's own albedo, or 1 under the Glossy
//!   Color pass). This is what the kernel reflects sharp lights through; its environment
//!   term is the split-sum approximation of the same integral, and the reference tells
//!   that approximation's error apart;
//! - `phong` and `sh`: Eq. 27's `(r+1)/(2 pi) max(R.w, 0)^r` (no cosine), cut by the
//!   tangent plane.
//!
//! `water` is `tint *` the shading of the reflection G-buffer's point with
//! its own material, seen from the water point (a background reflection is the light's
//! radiance along the mirrored view); background pixels are the light's radiance along
//! the camera ray (0 without a camera) with alpha 0. A material index missing from the
//! table shades black with alpha 1, as in the fast path.
//!
//! The light is [`ReferenceLight::EnvironmentMap`] (the full-resolution map through
//! [`Light::radiance`](crate::scene::Light::radiance): bilinear texels times strength;
//! a constant light is itself; an `sh` light is its expansion, not clamped) or
//! [`ReferenceLight::ShProjected`] (`light.sh_coefficients(order)`, the same projection
//! the fast path dots with, evaluated per direction and not clamped). Rendering both
//! tells band-limiting error (map vs projection) from visibility and exponentiation
//! error (projection vs fast path). Background and water-mirror pixels use the same
//! light model as the surfaces.
//!
//! The sharp lights are added by sampling each one's disk with the same exact visibility
//! (`sampled::sample_suns`): the scene's suns, and each point lamp's disk as seen from the
//! receiver, against only the spheres and terrain nearer than the lamp. Water mirroring
//! the sky shows the Sun lamps' disks, and water whose mirror ray meets a point lamp first
//! shows the lamp, as in the fast path ([`crate::shade::frame::mirrored_lamp`]).
//!
//! # Visibility (exact, f64)
//!
//! A direction `w` from the receiver `p` with normal `n` is visible when all of these
//! hold:
//!
//! - `n . w > 0`: the receiver's own surface is opaque (the tangent plane). The diffuse
//!   lobe is zero below it anyway; a Phong lobe reaching below the tangent plane is cut
//!   (the fast path's `tangent_occlusion` does the same).
//! - no sphere is hit by the ray `p + t w`, `t > 0`: for `|c - p| > r` the blocked
//!   directions are exactly the cap `w . (c - p)/|c - p| > sqrt(1 - r^2/|c - p|^2)`.
//!   **Receivers on a sphere** (the G-buffer's sphere pixels lie on the very sphere that
//!   is also a blocker): a point with `r (1 - 1e-4) <= |c - p| <= r`
//!   ([`SURFACE_BAND`]) sees that sphere as the half-space `w . (c - p) > 0`, the limit of
//!   the cap as `|c - p| -> r+`; for the sphere's own pixels this is the tangent plane,
//!   so a sphere never shadows itself beyond its own horizon, and rounding of f32
//!   positions slightly inside the surface cannot turn a pixel black. A receiver deeper
//!   inside a sphere is physically enclosed: everything is blocked (black). This
//!   differs from the fast path, which lets a receiver inside a blocker see the
//!   hemisphere away from the centre.
//! - the height field does not block it: a height field has no overhangs, so `w` is
//!   visible iff its elevation exceeds
//!   [`brute_force_horizon`](crate::heightfield::brute_force_horizon)`(p, azimuth(w))`,
//!   the exact horizon of the bilinear surface including the flat continuation. The
//!   horizon is computed once per azimuth (meridian, below) and reused for every polar
//!   sample. **Self-shadowing of terrain pixels**: `brute_force_horizon` treats a point
//!   within `1e-6 (1 + |z|)` of the surface as on it and takes the directional slope
//!   as the limit `t -> 0+`, so the surface does not shadow its own point; a point more
//!   than that *below* the surface would be buried (horizon `pi/2`, black). Every
//!   receiver (terrain or not: a sphere pixel at a contact, a mesh triangulated
//!   differently from the bilinear surface) is therefore first lifted onto the bilinear
//!   surface when it lies below it, `p.z = max(p.z, h(p.xy))`; points above keep their
//!   height and get the exact cast shadow of the terrain.
//!
//! # Two integrations, one visibility
//!
//! [`Integration::Meridians`] (below) is deterministic and exact to its tolerance, but
//! under a map it must resolve every texel column: a 240x135 frame under a 256x128 sky
//! ran for more than 8 minutes on 2 cores at tolerance 5e-3. [`Integration::Sampled`]
//! (`sampled.rs`) importance-samples the map and every lobe with the same exact
//! visibility test per direction, and stops on a statistical error estimate, far sooner
//! (docs/performance-log.md). `Auto` samples under maps and SH lights and
//! keeps the meridians for a constant light, where they are fast and the analytic tests
//! hold them to 5e-5.
//!
//! # Quadrature and convergence (meridians)
//!
//! The sphere is integrated by meridians: directions `w = sin(theta) (cos(phi) e1 +
//! sin(phi) e2) + cos(theta) e3` with the pole `e3` = world +Z when there is a height
//! field (so that each meridian is one world azimuth and needs one horizon) and the axis
//! of the sharpest lobe otherwise (the normal for diffuse, the mirrored view for Phong).
//! Along one meridian every visibility condition is an interval of `theta`, found in
//! closed form (a cap or a half-space meets a great half-circle in an arc `R cos(theta -
//! theta0) > k`; the horizon is `theta < pi/2 - sigma(phi)`), so the visible set is a
//! union of intervals computed exactly, with no sampling of the shadow boundary. Inside
//! each interval (cut again where a lobe's `max(., 0)` has its kink) the integrand is
//! smooth (up to the bilinear texel kinks of a map), and is integrated by adaptive
//! Gauss-Legendre (6 and 12 nodes on pieces of at most pi/8, smaller for sharp lobes or
//! maps, bisected while the two rules differ by more than their share of 1/8 of the
//! tolerance). The meridian integrals `M(phi)` are then averaged by the trapezoid rule
//! in `phi`, periodic. Level 0 has 32 meridians, more where a feature could fall between
//! them: at least 4 across the azimuth span `2 asin(sin(alpha)/sin(beta))` of every
//! sphere cap off the pole, half the map's width in texels, and about `21 sqrt(r + 1)`
//! for a Phong lobe off the pole (capped at 1024). Each level adds the midpoints (nested:
//! nothing is recomputed, so a level costs what all before it cost together). The error
//! estimate of level `k` is the larger of the last two changes, `|I_k - I_{k-1}|` and
//! `|I_{k-1} - I_{k-2}|` (largest channel), plus the bound of the meridian quadratures;
//! refinement stops at the first level whose estimate is at most `tolerance` (so at
//! least level 2), or at `max_level` (the pixel then counts as unconverged). Two changes
//! rather than one, because a single change can be small by luck while a small cap is
//! under-resolved: measured on sphere-over-plane, 32 and 64 meridians agreed to 1.2e-4
//! at a pixel where both were 2.6e-3 off.
//!
//! `M(phi)` is continuous in `phi` but not smooth where a shadow interval appears or
//! vanishes (a meridian tangent to a cap: the interval length grows like
//! `sqrt(phi - phi_t)`) or where the horizon has a kink, so the trapezoid rule converges
//! like `N^-1.5` to `N^-2` (measured at one penumbra pixel: error 2.6e-3, 7e-4, 1.3e-4,
//! 1.4e-5, 5e-6, 1.6e-6 for 64 .. 2048 meridians), not spectrally; visibility is never
//! sampled, so there is no `N^-1/2` or `N^-1` noise from shadow edges.
//!
//! Measured (`cargo test --test suite reference:: -- --nocapture`, tolerance 1e-3, max level 8):
//! over the five sphere-over-plane placements (5898 plane pixels at 48x27) the mean
//! absolute error against `1 - sin^2(alpha) cos(beta)` is 4.6e-5, the largest 9.8e-4,
//! every pixel converged; an unoccluded plane is 1 to rounding; height-field horizons
//! (wall, V valley, incline) match their closed forms to 4e-5 or better.
//!
//! # Cost
//!
//! One pixel costs `meridians x (visible pieces x 18)` light evaluations plus, with a
//! height field, one exact horizon per meridian (about `columns + rows` grid cells).

mod bounce;
mod integrate;
mod sampled;

pub use integrate::{
    integrate_point, GgxTerm, LightModel, LobeTerm, PointEstimate, ReferenceOccluders, MAX_REFERENCE_SH_ORDER,
    SURFACE_BAND,
};
pub use sampled::{sample_lamps, sample_point, sample_suns, TexelSampler, BASE_POINTS, REPLICATES};

use crate::logsh::Lobe;
use crate::scene::{Frame, Light, Material, Scene};
use crate::shade::frame::{mirrored_suns, pixel_source, PixelSource, Tint};
use crate::shade::glossy::{
    albedo_lookup, environment_albedo_table, ggx_alpha, lamp_fresnel, lamp_scale_table, GgxLit, SharpLobe,
};
use crate::shade::kernel::{glossy_map, SurfacePoint};
use crate::shade::point::{reflect_view, view_direction};
use crate::shade::GlossyMethod;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::sync::Mutex;

/// Which light the reference integrates.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReferenceLight {
    /// The full-resolution light (`Light::radiance`).
    EnvironmentMap,
    /// The light's order-`order` SH projection, evaluated per direction (not clamped).
    ShProjected { order: usize },
}

/// How the reference integrates each pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Integration {
    /// Sampling under an environment map or an SH light (the scene's or a projection),
    /// meridians under a constant light (where they are exact and fast).
    #[default]
    Auto,
    /// Deterministic, by meridians with exact visibility intervals (see the module doc):
    /// exact to the tolerance, slow under a map (every texel column is resolved).
    Meridians,
    /// Importance sampling of the map and the lobes ([`sampled`](self::sample_point)): an
    /// unbiased estimate whose error estimate is statistical (two standard errors).
    Sampled,
}

impl Integration {
    /// The method used for `light` (resolves `Auto`).
    pub fn for_light(self, light: &LightModel) -> Integration {
        match (self, light) {
            (Integration::Auto, LightModel::Direct(crate::scene::Light::Constant(_))) => Integration::Meridians,
            (Integration::Auto, _) => Integration::Sampled,
            (chosen, _) => chosen,
        }
    }
}

/// What to integrate and how precisely.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceOptions {
    pub light: ReferenceLight,
    pub integration: Integration,
    /// Convergence target: absolute error of the pixel's value (largest channel, after
    /// albedo, specular and tint), e.g. 1e-3.
    pub tolerance: f64,
    /// Most refinements (each doubles the meridians or the samples), at least 2: by
    /// meridians a pixel converges when two successive refinements both change it by at
    /// most `tolerance`; sampled, when the statistical error estimate is at most it.
    pub max_level: u32,
    /// Bounces of light off the proxies ([`bounce`]), 0 for direct light only.
    pub bounces: usize,
    /// Rays per receiver and bounce.
    pub bounce_samples: usize,
    /// The glossy lobe of Phong materials, as the kernel's `--glossy` names it.
    pub glossy: GlossyMethod,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        ReferenceOptions {
            light: ReferenceLight::EnvironmentMap,
            integration: Integration::Auto,
            tolerance: 1e-3,
            max_level: 6,
            bounces: 0,
            bounce_samples: 64,
            glossy: GlossyMethod::Ggx,
        }
    }
}

/// Most bounce rays per receiver accepted.
pub const MAX_BOUNCE_SAMPLES: usize = 65536;

/// Highest `max_level` accepted (level 20 is 32 million meridians per pixel).
pub const MAX_REFERENCE_LEVEL: u32 = 20;

impl ReferenceOptions {
    pub fn validate(&self) -> Result<(), String> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(format!("tolerance {} must be a finite number > 0", self.tolerance));
        }
        if self.max_level < 2 || self.max_level > MAX_REFERENCE_LEVEL {
            return Err(format!("max_level {} is out of range 2..={MAX_REFERENCE_LEVEL}", self.max_level));
        }
        if self.bounces > crate::shade::bounce::MAX_BOUNCES {
            return Err(format!("bounces {} is out of range 0..={}", self.bounces, crate::shade::bounce::MAX_BOUNCES));
        }
        if self.bounces > 0 && !(1..=MAX_BOUNCE_SAMPLES).contains(&self.bounce_samples) {
            return Err(format!("bounce samples {} is out of range 1..={MAX_BOUNCE_SAMPLES}", self.bounce_samples));
        }
        if let ReferenceLight::ShProjected { order } = self.light {
            if order == 0 || order > MAX_REFERENCE_SH_ORDER {
                return Err(format!("SH-projected light order {order} is out of range 1..={MAX_REFERENCE_SH_ORDER}"));
            }
        }
        Ok(())
    }
}

/// A reference frame: linear RGBA, row-major from the top row (alpha 1 on surfaces, 0 on
/// the background), with the convergence record.
#[derive(Clone, Debug)]
pub struct ReferenceFrame {
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<[f32; 4]>,
    /// Pixels whose error estimate is still above the tolerance at `max_level`.
    pub unconverged_pixels: usize,
    /// Largest per-pixel error estimate.
    pub max_estimated_error: f64,
    /// Per-pixel error estimate (0 on the background), row-major.
    pub estimated_error: Vec<f32>,
    /// The method used (never `Auto`).
    pub integration: Integration,
}

#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    #[error("reference options: {0}")]
    Options(String),
    /// What the frame lacks for its materials, or a bad height field (the same checks as
    /// the fast path).
    #[error(transparent)]
    Frame(#[from] crate::shade::ShadeError),
}

/// Renders the ground truth of one frame. `progress(rows_done)` is called once per
/// finished row, with `rows_done` increasing by one each call (calls are serialised).
pub fn render_reference(
    scene: &Scene,
    frame: &Frame,
    options: &ReferenceOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<ReferenceFrame, ReferenceError> {
    options.validate().map_err(ReferenceError::Options)?;
    crate::shade::frame::check_frame(scene, frame)?;
    let field = crate::shade::frame::height_field(scene, frame)?;
    let light = LightModel::new(&frame.light, &options.light).map_err(ReferenceError::Options)?;
    let integration = options.integration.for_light(&light);
    let environment = match integration {
        Integration::Sampled => TexelSampler::of(&light),
        _ => None,
    };
    let albedos = (options.bounces > 0).then(|| {
        let ground = frame.ground;
        crate::shade::bounce::SurfaceAlbedos::of(scene, frame, |i| {
            let p = frame.gbuffer.position[i].map(f64::from);
            let height = field.as_ref().map(|f| f.height_at(p[0], p[1])).or(ground);
            height.is_some_and(|h| (p[2] - h).abs() <= 1e-3 * (1.0 + p[2].abs()))
        })
    });
    let ctx = Context {
        albedos: albedos.as_ref(),
        materials: scene.kernel_materials(),
        ggx: GgxMaterial::of_scene(scene, &frame.light, options.glossy),
        integration,
        environment: environment.as_ref(),
        scene,
        frame,
        occluders: ReferenceOccluders {
            spheres: &frame.blockers,
            field: field.as_ref(),
            receiver_object: 0,
            ground: frame.ground,
        },
        light: &light,
        options,
    };
    let g = &frame.gbuffer;
    let (width, height) = (g.width, g.height);
    let mut rgba = vec![[0.0f32; 4]; width * height];
    let mut errors = vec![0.0f32; width * height];
    let done = Mutex::new(0usize);
    let (unconverged_pixels, max_estimated_error) = rgba
        .par_chunks_mut(width.max(1))
        .zip(errors.par_chunks_mut(width.max(1)))
        .enumerate()
        .map(|(y, (row, row_errors))| {
            let mut unconverged = 0;
            let mut worst = 0.0f64;
            for x in 0..row.len() {
                let (px, estimate) = ctx.pixel(x, y, width);
                row[x] = px;
                row_errors[x] = estimate.error as f32;
                worst = worst.max(estimate.error);
                unconverged += usize::from(!estimate.converged);
            }
            let mut d = done.lock().unwrap_or_else(|e| e.into_inner());
            *d += 1;
            progress(*d);
            (unconverged, worst)
        })
        .reduce(|| (0, 0.0), |a, b| (a.0 + b.0, a.1.max(b.1)));
    Ok(ReferenceFrame {
        width,
        height,
        rgba,
        unconverged_pixels,
        max_estimated_error,
        estimated_error: errors,
        integration,
    })
}

/// A Phong material's glossy lobe as the kernel's `--glossy ggx` reflects its sharp
/// lights: GGX's BRDF of the material's width with the Fresnel term of reflectance
/// `fresnel`, times `scale` at `n . v` ([`lamp_scale_table`]).
struct GgxMaterial {
    alpha: f64,
    fresnel: f64,
    scale: Vec<f32>,
}

impl GgxMaterial {
    /// Every Phong material's, where the kernel shades `light`'s glossy term as GGX: with
    /// `--glossy ggx`, under a light with a map to prefilter ([`glossy_map`]).
    fn of_scene(scene: &Scene, light: &Light, glossy: GlossyMethod) -> BTreeMap<u32, GgxMaterial> {
        if glossy != GlossyMethod::Ggx || glossy_map(light).is_none() {
            return BTreeMap::new();
        }
        let fresnel = lamp_fresnel(scene);
        let ggx = |(&index, material): (&u32, &Material)| {
            let Material::Phong { exponent, .. } = material else { return None };
            let alpha = ggx_alpha(f64::from(*exponent));
            let lobe = SharpLobe::Ggx { alpha };
            let fresnel = fresnel.get(&index).copied().unwrap_or(1.0);
            let scale = lamp_scale_table(lobe, &environment_albedo_table(lobe, scene.colour_passes()), fresnel);
            Some((index, GgxMaterial { alpha, fresnel, scale }))
        };
        scene.materials.iter().filter_map(ggx).collect()
    }

    /// `phong`'s term (its axis, the mirrored view, and colour) reflected through GGX's
    /// BRDF, seen along unit `view` by a receiver of unit normal `n`.
    fn term(&self, phong: LobeTerm, n: [f64; 3], view: [f64; 3]) -> LobeTerm {
        let n_v = crate::vector::dot(n, view);
        let scale = albedo_lookup(&self.scale, n_v);
        LobeTerm {
            scale: phong.scale.map(|c| c * scale),
            ggx: Some(GgxTerm { brdf: GgxLit::new(self.alpha, self.fresnel, n_v), normal: n, view }),
            ..phong
        }
    }
}

/// What every pixel's integration reads.
struct Context<'a> {
    scene: &'a Scene,
    /// What the proxies reflect with, where bounces are asked for.
    albedos: Option<&'a crate::shade::bounce::SurfaceAlbedos>,
    /// The lobes and their colours as the kernel shades them, the pixels' tints on top
    /// ([`Scene::kernel_materials`]).
    materials: BTreeMap<u32, Material>,
    /// The Phong materials whose glossy lobe is GGX's BRDF ([`GgxMaterial`]).
    ggx: BTreeMap<u32, GgxMaterial>,
    frame: &'a Frame,
    occluders: ReferenceOccluders<'a>,
    light: &'a LightModel<'a>,
    options: &'a ReferenceOptions,
    integration: Integration,
    /// The map's texel sampler when sampling.
    environment: Option<&'a TexelSampler>,
}

impl Context<'_> {
    fn light_along(&self, dir: [f64; 3]) -> [f64; 3] {
        let l = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        if !(l > 0.0) {
            return [0.0; 3];
        }
        self.light.radiance(dir.map(|c| c / l))
    }

    /// Shading of `point`, its diffuse lobe times `tint.diffuse` and its glossy lobe
    /// times `tint.specular`. `seed` fixes a sampled pixel's randomisation.
    fn surface(&self, point: SurfacePoint, tint: Tint, seed: u64) -> PointEstimate {
        let (p, n, view) = (point.position, point.normal, point.view_origin);
        let scaled = |c: [f32; 3], t: [f32; 3]| [0, 1, 2].map(|k| f64::from(c[k]) * f64::from(t[k]));
        let terms = match self.materials.get(&point.material) {
            Some(Material::Diffuse { albedo }) | Some(Material::Heightfield { albedo }) => {
                vec![LobeTerm { lobe: Lobe::Diffuse, axis: n, scale: scaled(*albedo, tint.diffuse), ggx: None }]
            }
            Some(Material::Phong { albedo, specular, exponent }) => {
                let (axis, scale) = (reflect_view(view, p, n), scaled(*specular, tint.specular));
                let phong = LobeTerm { lobe: Lobe::Phong { exponent: f64::from(*exponent) }, axis, scale, ggx: None };
                let glossy = match self.ggx.get(&point.material) {
                    Some(ggx) => ggx.term(phong, n, view_direction(view, p, n)),
                    None => phong,
                };
                vec![LobeTerm { lobe: Lobe::Diffuse, axis: n, scale: scaled(*albedo, tint.diffuse), ggx: None }, glossy]
            }
            Some(Material::Water { .. }) | None => Vec::new(),
        };
        let estimate = self.lit(p, n, point.object, &terms, self.options.tolerance, seed);
        let Some(albedos) = self.albedos else { return estimate };
        // The bounce off the diffuse lobe (the glossy lobe's is left out).
        let bounce = self.bounced(albedos, p, n, point.object, self.options.bounces, seed);
        let diffuse = terms.iter().find(|t| matches!(t.lobe, Lobe::Diffuse)).map_or([0.0; 3], |t| t.scale);
        PointEstimate { rgb: std::array::from_fn(|c| estimate.rgb[c] + diffuse[c] * bounce[c]), ..estimate }
    }

    /// The direct light at `p` (normal `n`, on `object`) through `terms`: the
    /// environment, the suns and the lamps, to `tolerance`.
    fn lit(
        &self,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
        terms: &[LobeTerm],
        tolerance: f64,
        seed: u64,
    ) -> PointEstimate {
        let occluders = ReferenceOccluders { receiver_object: object, ..self.occluders };
        let max_level = self.options.max_level;
        let environment = match self.integration {
            Integration::Sampled => {
                sample_point(occluders, self.light, self.environment, p, n, terms, tolerance, max_level, seed)
            }
            _ => integrate_point(occluders, self.light, p, n, terms, tolerance, max_level),
        };
        if self.frame.suns.is_empty() && self.frame.points.is_empty() {
            return environment;
        }
        // The sharp lights to half the tolerance (their part is sampled whatever the
        // integration), split between the suns and the lamps.
        let sharp = 0.5 * tolerance / (!self.frame.suns.is_empty() as u8 + !self.frame.points.is_empty() as u8) as f64;
        let suns = sample_suns(occluders, &self.frame.suns, p, n, terms, sharp, max_level, seed ^ 0x5u64);
        let lamps = sample_lamps(occluders, &self.frame.points, p, n, terms, sharp, max_level, seed ^ 0x6u64);
        PointEstimate {
            meridians: environment.meridians,
            level: environment.level,
            ..environment.plus(&suns).plus(&lamps)
        }
    }

    fn pixel(&self, x: usize, y: usize, width: usize) -> ([f32; 4], PointEstimate) {
        let seed = (y * width + x) as u64;
        let out = |c: [f64; 3], alpha: f32| [c[0] as f32, c[1] as f32, c[2] as f32, alpha];
        let exact =
            |c: [f64; 3]| PointEstimate { rgb: c, error: 0.0, level: 0, converged: true, meridians: 0, evaluations: 0 };
        let tinted = |tint: [f32; 3], c: [f64; 3]| [0, 1, 2].map(|k| f64::from(tint[k]) * c[k]);
        // The same walk as the fast path's, which the reference checks.
        let estimate = match pixel_source(&self.scene.materials, self.frame, x, y) {
            PixelSource::Background { ray } => {
                let sky = ray.map_or([0.0; 3], |d| self.light_along(d));
                return (out(sky, 0.0), exact(sky));
            }
            PixelSource::WaterLamp { tint, radiance } => exact(tinted(tint, radiance.map(f64::from))),
            PixelSource::WaterSky { tint, mirror } => {
                let sky = self.light_along(mirror);
                let suns = mirrored_suns(self.frame, mirror);
                exact(tinted(tint, [0, 1, 2].map(|k| sky[k] + f64::from(suns[k]))))
            }
            PixelSource::Surface { point, tint } => self.surface(point, tint, seed),
        };
        (out(estimate.rgb, 1.0), estimate)
    }
}
