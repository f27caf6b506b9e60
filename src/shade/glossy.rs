//! Sharp glossy lobes outside SH: the split sum of Karis 2013 ("Real Shading in Unreal
//! Engine 4"), with log-SH visibility as the specular occlusion.
//!
//! Order-n SH holds a lobe no narrower than about `pi / n` (paper 000, Fig. 7): at order
//! 4 a near-mirror comes out as a dull blob 0.3 away from Cycles. Here the glossy term of
//! a `phong` material is
//!
//! ```text
//! glossy = specular * A(n . v) * P(R) * O
//! ```
//!
//! - `P(R)`: the environment prefiltered with the lobe about the mirror direction `R`,
//!   `integral L(w) lobe(R . w) dw` with the lobe normalised over the sphere, read
//!   bilinearly from a map whose resolution follows the lobe's width ([`Prefiltered`]).
//! - `A(n . v)`: the lobe's albedo, what a white sky reflects: for the GGX lobe, GGX's
//!   directional albedo with no Fresnel term (Cycles' Glossy BSDF: single scattering,
//!   height-correlated Smith masking, so the cosine, the masking and the lower hemisphere
//!   are all in it); for the Phong lobe, the part of it above the tangent plane.
//! - `O`: the specular occlusion by the blockers and the height field, in `[0, 1]`. For
//!   a lobe order n resolves, log-SH's own, `lum(exp*(V + lobe) . L) / lum(exp*(lobe) .
//!   L)` with `V` their log visibility (the height field's only above the horizontal,
//!   since the map's black lower hemisphere already darkens the lobe below it: counting it
//!   twice left a rough lobe on a height field 15 % too dark against the reference), the
//!   log-SH Phong lobe of the same width and `L` the light's SH vector. A sharper lobe's would be blurred over the order's `pi / n`
//!   (a mirror reflecting a sphere came out 0.4 where the truth is 0), so its core (the
//!   cone holding 80 % of it, [`SharpLobe::core_radius`]) is tested as a sun's disk is
//!   (`super::sun`: 32 directions against the spheres themselves and the horizon along
//!   its azimuth), each direction weighted by the lobe ([`cone_weights`]); between the
//!   two, a blend ([`cone_share`]). The tangent plane and the ground plane are in
//!   neither: `A` holds the first exactly, and the second is taken out of the map itself
//!   (the map is prefiltered with its lower hemisphere black when the scene has a ground
//!   plane), where order 4 would blur either over tens of degrees.
//!
//! The GGX lobe in reflected space is the split sum's `n = v = R` case: with the half
//! vector `h` at half the angle `theta` from `R`, `lobe(theta) = D(cos(theta / 2)) / 4`,
//! `D` the GGX normal distribution of width `alpha`, which integrates to 1 over the
//! sphere. Its `alpha` is the one the exporter mapped to the Phong exponent,
//! `r = 1 / (2 alpha^2) - 1/2` (`blender_scripts/logsh_exporter/exporter.py`), so that
//! both lobes have the same peak, `(r + 1/2) / (2 pi)` against `(r + 1) / (2 pi)`.

use super::sun::{disk_pattern, DISK_DIRECTIONS};
use crate::memo::Memo;
use crate::scene::light::{lookup_coordinates, BilinearTaps, EnvironmentMap};
use crate::scene::{Material, Scene};
use crate::vector::dot;
use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::sync::{Arc, OnceLock};

/// The shape of a sharp lobe about `R` (`--glossy`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SharpLobe {
    /// GGX of width `alpha` in reflected space, with GGX's directional albedo.
    Ggx { alpha: f64 },
    /// `(r + 1) / (2 pi) max(cos theta, 0)^r` (paper 000, Eq. 27), clipped by the
    /// tangent plane.
    Phong { exponent: f64 },
}

/// GGX width `alpha` of the Phong exponent the exporter writes for it (inverse of
/// `r = 1 / (2 alpha^2) - 1/2`).
pub fn ggx_alpha(exponent: f64) -> f64 {
    (0.5 / (exponent + 0.5)).sqrt()
}

/// GGX normal distribution at `cos theta_h = mu`, normalised as `integral D cos = 1`.
fn ggx_distribution(alpha: f64, mu: f64) -> f64 {
    let a2 = alpha * alpha;
    let d = mu * mu * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d)
}

/// Smith's `Lambda` for GGX at `cos theta = mu` (height-correlated masking,
/// `G2 = 1 / (1 + Lambda(v) + Lambda(l))`).
fn ggx_lambda(alpha: f64, mu: f64) -> f64 {
    let mu2 = (mu * mu).max(1e-12);
    0.5 * ((1.0 + alpha * alpha * (1.0 - mu2) / mu2).sqrt() - 1.0)
}

/// Schlick's Fresnel term of reflectance `f0` at `v . h = cosine`; 1 throughout for
/// `f0 = 1`.
fn schlick(f0: f64, cosine: f64) -> f64 {
    f0 + (1.0 - f0) * (1.0 - cosine.clamp(0.0, 1.0)).powi(5)
}

/// Reflectance at normal incidence up to which [`Fresnel`] is a dielectric's (IOR 2.6;
/// glass is 0.04, water 0.02, diamond 0.17).
pub const DIELECTRIC_F0: f64 = 0.2;
/// Reflectance at normal incidence from which [`Fresnel`] is a metal's.
pub const METAL_F0: f64 = 0.4;

/// The Fresnel term of a surface that reflects `f0` at normal incidence, as Cycles'
/// Principled BSDF has it: a dielectric layer reflects by the Fresnel equations of its
/// IOR, `(1 + sqrt f0) / (1 - sqrt f0)` (unpolarised, Walter et al. 2007, "Microfacet
/// Models for Refraction", Eq. 22), and a metal by Schlick's approximation (its F82 tint
/// white, the default). A reflectance up to [`DIELECTRIC_F0`] is read as a dielectric's,
/// from [`METAL_F0`] as a metal's, and one between as their mix. At `v . h = 0.6`, where
/// a lamp behind a glass-like surface seen at `n . v = 0.35` meets its highlight, the
/// equations give 0.063 and Schlick 0.049.
#[derive(Clone, Copy, Debug)]
pub struct Fresnel {
    f0: f64,
    /// The IOR's square.
    eta_squared: f64,
    /// The share of Schlick's term.
    metal: f64,
}

impl Fresnel {
    pub fn new(f0: f64) -> Self {
        let f0 = f0.clamp(0.0, 1.0);
        let metal = ((f0 - DIELECTRIC_F0) / (METAL_F0 - DIELECTRIC_F0)).clamp(0.0, 1.0);
        // Capped where the dielectric has no share, so that a reflectance of 1 (no Fresnel
        // term) still has a finite IOR.
        let root = f0.sqrt().min(METAL_F0.sqrt());
        let eta = (1.0 + root) / (1.0 - root);
        Fresnel { f0, eta_squared: eta * eta, metal }
    }

    /// The reflectance at `v . h = cosine`.
    #[inline(always)]
    pub fn at(&self, cosine: f64) -> f64 {
        let schlick = schlick(self.f0, cosine);
        if self.metal >= 1.0 {
            return schlick;
        }
        let c = cosine.clamp(0.0, 1.0);
        let g = (self.eta_squared - 1.0 + c * c).sqrt();
        let dielectric = if g + c > 1e-12 {
            let a = (g - c) / (g + c);
            let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
            0.5 * a * a * (1.0 + b * b)
        } else {
            0.0
        };
        dielectric + self.metal * (schlick - dielectric)
    }
}

/// GGX's BRDF times the cosine and the [`Fresnel`] term, `F(v . h) D(n . h) G2(v, w) /
/// (4 n . v)` for `n . w > 0`, given the reflectance `f0` at normal incidence, `n . v`,
/// `n . w` and `v . w`: what a sharp light at `w` reflects towards `v` per unit
/// irradiance. With `f0 = 1`, Cycles' single-scattering Glossy BSDF of colour 1, whose
/// integral over `w` is [`SharpLobe::albedo`] (within 0.01, tested). The split sum's lobe
/// about `R` ([`SharpLobe::value`]) is the case `n = v = R`; away from it the true lobe
/// leans towards the normal and is cut by the tangent plane ([`lamp_scale_table`]).
pub fn ggx_lit(alpha: f64, f0: f64, n_v: f64, n_w: f64, v_w: f64) -> f64 {
    GgxLit::new(alpha, f0, n_v).value(n_w, v_w)
}

/// [`ggx_lit`] for one view: what does not depend on the light's direction, worked out
/// once for a disk's directions.
#[derive(Clone, Copy, Debug)]
pub struct GgxLit {
    alpha: f64,
    fresnel: Fresnel,
    mu: f64,
    /// `1 + Lambda(n . v)`.
    one_plus_lambda_v: f64,
}

impl GgxLit {
    pub fn new(alpha: f64, f0: f64, n_v: f64) -> Self {
        let mu = n_v.clamp(1e-4, 1.0);
        Self { alpha, fresnel: Fresnel::new(f0), mu, one_plus_lambda_v: 1.0 + ggx_lambda(alpha, mu) }
    }

    /// [`ggx_lit`] at `n . w` and `v . w`.
    #[inline(always)]
    pub fn value(&self, n_w: f64, v_w: f64) -> f64 {
        let half_length_squared = 2.0 + 2.0 * v_w;
        if n_w <= 0.0 || half_length_squared <= 1e-12 {
            return 0.0;
        }
        let half_length = half_length_squared.sqrt();
        let n_h = ((self.mu + n_w) / half_length).min(1.0);
        let g2 = 1.0 / (self.one_plus_lambda_v + ggx_lambda(self.alpha, n_w));
        self.fresnel.at(0.5 * half_length) * ggx_distribution(self.alpha, n_h) * g2 / (4.0 * self.mu)
    }
}

/// What a sharp light's glossy term is scaled by at `n . v` ([`ALBEDO_ENTRIES`] entries,
/// read with [`albedo_lookup`]), given the lobe's `albedo` table (what the environment's
/// glossy term is scaled by: GGX's own albedo, or 1 where the Glossy Color pass holds
/// Cycles' albedo of the specular layer) and the reflectance `f0` [`ggx_lit`] is given.
///
/// - GGX: the light is reflected through [`ggx_lit`], whose integral is the lobe's albedo
///   with that Fresnel term, `E(n . v)` ([`SharpLobe::fresnel_albedo`]), so the scale is
///   `albedo / E`: 1 on converted materials (`f0 = 1`, Cycles' Glossy BSDF exactly);
///   under the Glossy Color pass, the pass's albedo spread as GGX and Fresnel spread it.
///   `E` is floored at [`LAMP_ALBEDO_FLOOR`] of `albedo`.
/// - Phong: the light is reflected through the lobe about `R`, scaled by `albedo` as the
///   environment's term is.
///
/// On `blender_scripts/scenes/principled_tiles.py` (Principled tiles under a Sun lamp
/// alone), against Cycles as authored: 0.0118 where the lobe about `R` was 0.0570, every
/// tile darker then (docs/method/materials.md).
pub fn lamp_scale_table(lobe: SharpLobe, albedo: &[f32], f0: f64) -> Vec<f32> {
    match lobe {
        SharpLobe::Ggx { alpha } => {
            let own = fresnel_albedo_table(alpha, f0);
            albedo.iter().zip(&own).map(|(&a, &own)| a / own.max(LAMP_ALBEDO_FLOOR * a)).collect()
        }
        SharpLobe::Phong { .. } => albedo.to_vec(),
    }
}

/// GGX's albedo with the [`Fresnel`] term of reflectance `f0`
/// ([`SharpLobe::fresnel_albedo`]) over `n . v`, as [`albedo_table`] holds it at `f0 = 1`;
/// integrated once per lobe, reflectance and process.
fn fresnel_albedo_table(alpha: f64, f0: f64) -> Vec<f32> {
    static TABLES: Memo<(u64, u64), Vec<f32>> = Memo::new();
    let lobe = SharpLobe::Ggx { alpha };
    let table = TABLES.get_or_build((alpha.to_bits(), f0.to_bits()), || {
        (0..ALBEDO_ENTRIES).map(|i| lobe.fresnel_albedo(i as f64 / (ALBEDO_ENTRIES - 1) as f64, f0) as f32).collect()
    });
    table.to_vec()
}

/// The least reflectance [`lamp_fresnel`] gives: water's (IOR 1.33).
pub const MIN_LAMP_FRESNEL: f64 = 0.02;

/// Each Phong material's reflectance at normal incidence for the Fresnel term the sharp
/// lights reflect with ([`ggx_lit`]), where the colours come from the G-buffer's passes,
/// at least [`MIN_LAMP_FRESNEL`]:
///
/// - the table's `fresnel` where the exporter gives it (a Principled BSDF whose IOR,
///   Specular IOR Level, Specular Tint and Metallic are not driven by nodes);
/// - otherwise worked out from the Glossy Color pass, Cycles' albedo of the specular
///   layer, Fresnel included, whose mean over the material's pixels the table entry holds
///   (the exporter's `fit_to_passes`; [`fresnel_from_albedo`], the mean of R, G and B).
///   The mean is read at `n . v = 1/2`, so a material seen at other angles is given
///   another reflectance: a glass-like tile (0.04) seen at `n . v` 0.3 to 0.45 is read as
///   0.078, and its highlight under a lamp behind it is 6 % of its light too bright
///   (`blender_scripts/scenes/principled_tiles.py`).
///
/// Empty without passes: the converted materials are Glossy BSDFs, which have no Fresnel
/// term.
pub fn lamp_fresnel(scene: &Scene) -> BTreeMap<u32, f64> {
    if !scene.colour_passes() {
        return BTreeMap::new();
    }
    let phong = |(&index, material): (&u32, &Material)| {
        let Material::Phong { specular, exponent, .. } = material else { return None };
        let from_pass = || {
            let albedo = specular.iter().map(|&c| f64::from(c)).sum::<f64>() / 3.0;
            fresnel_from_albedo(ggx_alpha(f64::from(*exponent)), albedo, MIN_LAMP_FRESNEL)
        };
        let given = scene.fresnel.get(&index).map(|&f0| f0.max(MIN_LAMP_FRESNEL));
        Some((index, given.unwrap_or_else(from_pass)))
    };
    scene.materials.iter().filter_map(phong).collect()
}

/// GGX's BRDF is smooth over a disk ([`smooth_over_disk`]) where the square of its
/// width `alpha n . v` and that of the disk's height above the tangent plane are each at
/// least this many times the disk's `1 - cos(half-angle)`: both about 16 times the
/// half-angle.
pub const SMOOTH_OVER_DISK: f64 = 512.0;

/// Whether GGX's BRDF of width `alpha` seen at `n . v = n_v` is smooth over a disk of
/// `1 - cos(half-angle)` = `one_minus_cos` whose axis is at `n . axis = n_axis`, so that an
/// open disk's mean of it is its value at the axis, where the BRDF costs 32 times less:
/// within 0.1 % (tested against the 32 directions' mean, `sun.rs`). A grazing view
/// narrows the lobe about the mirror direction by about `n . v`, and nearer the tangent
/// plane the masking changes across the disk.
pub fn smooth_over_disk(alpha: f64, n_v: f64, one_minus_cos: f64, n_axis: f64) -> bool {
    let least = SMOOTH_OVER_DISK * one_minus_cos;
    let width = alpha * n_v.max(0.0);
    width * width >= least && n_axis * n_axis >= least
}

/// The reflectance at normal incidence `f0` whose GGX albedo with Fresnel
/// ([`SharpLobe::fresnel_albedo`], which rises with `f0`) is `albedo` at `n . v = 1/2`,
/// between `least` and 1: what a Glossy Color pass's mean says of a Principled BSDF's
/// specular layer (Cycles' albedo also holds its multiple scattering, which this reads as
/// a higher `f0`: 0.9 of a rough dielectric's single-scattering albedo or less). Worked
/// out once per process and key: every frame's lighting asks for it.
pub fn fresnel_from_albedo(alpha: f64, albedo: f64, least: f64) -> f64 {
    static FOUND: Memo<(u64, u64, u64), f64> = Memo::new();
    *FOUND.get_or_build((alpha.to_bits(), albedo.to_bits(), least.to_bits()), || bisect_fresnel(alpha, albedo, least))
}

/// [`fresnel_from_albedo`] worked out: the albedo rises with the reflectance.
fn bisect_fresnel(alpha: f64, albedo: f64, least: f64) -> f64 {
    let lobe = SharpLobe::Ggx { alpha };
    let at = |f0: f64| lobe.fresnel_albedo(0.5, f0);
    let (mut low, mut high) = (least, 1.0);
    if at(low) >= albedo {
        return low;
    }
    if at(high) <= albedo {
        return high;
    }
    for _ in 0..FRESNEL_BISECTIONS {
        let middle = 0.5 * (low + high);
        if at(middle) < albedo {
            low = middle;
        } else {
            high = middle;
        }
    }
    0.5 * (low + high)
}

/// Halvings of [`fresnel_from_albedo`]'s interval: the reflectance to 1e-6.
const FRESNEL_BISECTIONS: usize = 20;

/// The least share of the environment's albedo a sharp light's scale divides by
/// ([`lamp_scale_table`]). The least GGX albedo with Fresnel is about 0.006 (alpha 1,
/// `n . v = 1`, `f0` 0.02: a rough dielectric reflects little), well above it.
pub const LAMP_ALBEDO_FLOOR: f32 = 1e-3;

impl SharpLobe {
    /// The lobe's value at `cos theta = z` from its axis, normalised over the sphere.
    pub fn value(self, z: f64) -> f64 {
        match self {
            SharpLobe::Ggx { alpha } => ggx_distribution(alpha, ((1.0 + z.clamp(-1.0, 1.0)) * 0.5).sqrt()) / 4.0,
            SharpLobe::Phong { exponent } => {
                if z <= 0.0 {
                    0.0
                } else {
                    (exponent + 1.0) / (2.0 * PI) * z.powf(exponent)
                }
            }
        }
    }

    /// The angle from the axis at which the lobe falls to half its peak: the scale that
    /// sets a prefiltered map's resolution.
    pub fn half_width(self) -> f64 {
        match self {
            // D = D_max / 2 where cos^2 theta_h = (1 - sqrt(2) a^2) / (1 - a^2); the
            // reflected angle is twice the half vector's.
            SharpLobe::Ggx { alpha } => {
                let a2 = alpha * alpha;
                let mu2 = ((1.0 - std::f64::consts::SQRT_2 * a2) / (1.0 - a2)).clamp(0.0, 1.0);
                2.0 * mu2.sqrt().acos()
            }
            SharpLobe::Phong { exponent } => 0.5f64.powf(1.0 / exponent).acos(),
        }
    }

    /// The lobe convolved with a patch of angular radius `patch`, to first order: GGX's
    /// reflected half-width is about twice its `alpha`, so `alpha' = sqrt(alpha^2 +
    /// (patch / 2)^2`, and a Phong lobe takes the exponent of that `alpha`. A sun's disk
    /// reflects through this lobe: 32 directions over a 0.5 degree disk stand for patches
    /// of 0.09 degrees, and a mirror's lobe (0.06 degrees) between them would turn its
    /// highlight into sparkles.
    pub fn widened(self, patch: f64) -> SharpLobe {
        let widen = |alpha: f64| (alpha * alpha + 0.25 * patch * patch).sqrt();
        match self {
            SharpLobe::Ggx { alpha } => SharpLobe::Ggx { alpha: widen(alpha) },
            SharpLobe::Phong { exponent } => {
                let alpha = widen(ggx_alpha(exponent));
                SharpLobe::Phong { exponent: (0.5 / (alpha * alpha) - 0.5).clamp(f64::MIN_POSITIVE, exponent) }
            }
        }
    }

    /// The angle from the axis within which the lobe holds 80 % of its mass: the cone
    /// whose directions the specular occlusion tests ([`cone_weights`]).
    pub fn core_radius(self) -> f64 {
        match self {
            // GGX's mass within theta_h is tan^2 / (alpha^2 + tan^2): 4/5 at tan = 2 alpha.
            SharpLobe::Ggx { alpha } => (2.0 * (2.0 * alpha).atan()).min(FRAC_PI_2),
            // Phong's mass within theta is 1 - cos^(r + 1) theta.
            SharpLobe::Phong { exponent } => 0.2f64.powf(1.0 / (exponent + 1.0)).acos().min(FRAC_PI_2),
        }
    }

    /// The lobe's albedo at `n . v = mu` (module doc): what it reflects of a white sky
    /// above the tangent plane, by a 64 x 64 midpoint rule over its sampling
    /// distribution (GGX: half vectors drawn from `D cos`; Phong: directions about `R`).
    pub fn albedo(self, mu: f64) -> f64 {
        self.fresnel_albedo(mu, 1.0)
    }

    /// [`Self::albedo`] with GGX's light weighted by the [`Fresnel`] term of reflectance
    /// `f0` ([`ggx_lit`]); a Phong lobe's is its albedo.
    pub fn fresnel_albedo(self, mu: f64, f0: f64) -> f64 {
        const STEPS: usize = 64;
        let fresnel = Fresnel::new(f0);
        let mu = mu.clamp(1e-4, 1.0);
        let v = [(1.0 - mu * mu).sqrt(), 0.0, mu];
        let mut sum = 0.0;
        for i in 0..STEPS {
            let xi = (i as f64 + 0.5) / STEPS as f64;
            for j in 0..STEPS {
                let phi = 2.0 * PI * (j as f64 + 0.5) / STEPS as f64;
                sum += match self {
                    SharpLobe::Ggx { alpha } => {
                        // h with pdf D cos: tan theta_h = alpha sqrt(xi / (1 - xi)).
                        let theta_h = (alpha * (xi / (1.0 - xi)).sqrt()).atan();
                        let h = [theta_h.sin() * phi.cos(), theta_h.sin() * phi.sin(), theta_h.cos()];
                        let vh = dot(v, h);
                        let l_z = 2.0 * vh * h[2] - v[2];
                        if vh <= 0.0 || l_z <= 0.0 {
                            0.0
                        } else {
                            // f cos / pdf(l) = G2 (v . h) / ((n . v) (n . h)).
                            let g2 = 1.0 / (1.0 + ggx_lambda(alpha, mu) + ggx_lambda(alpha, l_z));
                            fresnel.at(vh) * g2 * vh / (mu * h[2])
                        }
                    }
                    SharpLobe::Phong { exponent } => {
                        // w about R with pdf lobe: cos theta = xi^(1 / (r + 1)).
                        let z = xi.powf(1.0 / (exponent + 1.0));
                        let s = (1.0 - z * z).max(0.0).sqrt();
                        let r = [-v[0], 0.0, v[2]];
                        // R's frame: R, t = (R_z, 0, -R_x) in its plane, and Y.
                        let w_z = z * r[2] + s * phi.cos() * (-r[0]);
                        f64::from(u8::from(w_z > 0.0))
                    }
                };
            }
        }
        sum / (STEPS * STEPS) as f64
    }

    /// The share of the lobe about `R`, as the map is prefiltered with it, that lies above
    /// the tangent plane at `n . R = mu`, by a 64 x 64 midpoint rule over its distribution
    /// (half vectors drawn from `D cos` about `R`, each direction at twice their angle); 1
    /// for a Phong lobe, whose albedo already holds that share.
    pub fn share_above_tangent_plane(self, mu: f64) -> f64 {
        const STEPS: usize = 64;
        let SharpLobe::Ggx { alpha } = self else { return 1.0 };
        let mu = mu.clamp(0.0, 1.0);
        // R = (sqrt(1 - mu^2), 0, mu); t = (-mu, 0, sqrt(1 - mu^2)) in its plane.
        let across = (1.0 - mu * mu).sqrt();
        let mut above = 0usize;
        for i in 0..STEPS {
            let xi = (i as f64 + 0.5) / STEPS as f64;
            let theta = 2.0 * (alpha * (xi / (1.0 - xi)).sqrt()).atan();
            for j in 0..STEPS {
                let phi = 2.0 * PI * (j as f64 + 0.5) / STEPS as f64;
                above += usize::from(mu * theta.cos() + across * theta.sin() * phi.cos() > 0.0);
            }
        }
        above as f64 / (STEPS * STEPS) as f64
    }
}

/// The lobe's value at each direction of its core's [`super::sun::DiskDirections`] (the disk of
/// [`SharpLobe::core_radius`] about the lobe's axis), normalised to sum to 1: the
/// weights of the cone's visibility in the specular occlusion.
pub fn cone_weights(lobe: SharpLobe) -> [f64; DISK_DIRECTIONS] {
    let one_minus_cos = 1.0 - lobe.core_radius().cos();
    let values = disk_pattern().map(|[x, y]| lobe.value(1.0 - one_minus_cos * (x * x + y * y)));
    let sum: f64 = values.iter().sum();
    values.map(|v| v / sum)
}

/// How much of the specular occlusion comes from the cone test rather than from log-SH
/// at order `order`: 1 for a lobe whose core is at most half the angle order-n SH
/// resolves (`pi / n`), 0 from that angle on, linear between.
pub fn cone_share(lobe: SharpLobe, order: usize) -> f64 {
    let resolved = PI / order as f64;
    (2.0 - 2.0 * lobe.core_radius() / resolved).clamp(0.0, 1.0)
}

/// Entries of a lobe's albedo table over `n . v` in `[0, 1]`.
pub const ALBEDO_ENTRIES: usize = 33;

/// `A(mu)` at `mu = i / (ALBEDO_ENTRIES - 1)`, read linearly ([`albedo_lookup`]).
/// Each lobe's table is worked out once per process ([`crate::memo`]).
pub fn albedo_table(lobe: SharpLobe) -> Vec<f32> {
    static TABLES: Memo<(bool, u64), Vec<f32>> = Memo::new();
    let key = match lobe {
        SharpLobe::Ggx { alpha } => (true, alpha.to_bits()),
        SharpLobe::Phong { exponent } => (false, exponent.to_bits()),
    };
    let table = TABLES.get_or_build(key, || {
        (0..ALBEDO_ENTRIES).map(|i| lobe.albedo(i as f64 / (ALBEDO_ENTRIES - 1) as f64) as f32).collect()
    });
    table.to_vec()
}

/// What the environment's glossy term is scaled by over `n . v`: the lobe's own albedo
/// ([`albedo_table`]), or 1 where the G-buffer's Glossy Color pass holds Cycles' albedo
/// and multiplies the lobe per pixel.
pub fn environment_albedo_table(lobe: SharpLobe, colour_passes: bool) -> Vec<f32> {
    if colour_passes {
        vec![1.0; ALBEDO_ENTRIES]
    } else {
        albedo_table(lobe)
    }
}

/// [`SharpLobe::share_above_tangent_plane`] over `n . R` in `[0, 1]`, [`ALBEDO_ENTRIES`]
/// entries read with [`albedo_lookup`], worked out once per lobe and process.
pub fn share_above_table(lobe: SharpLobe) -> Vec<f32> {
    static TABLES: Memo<(bool, u64), Vec<f32>> = Memo::new();
    let key = match lobe {
        SharpLobe::Ggx { alpha } => (true, alpha.to_bits()),
        SharpLobe::Phong { exponent } => (false, exponent.to_bits()),
    };
    let table = TABLES.get_or_build(key, || {
        (0..ALBEDO_ENTRIES)
            .map(|i| lobe.share_above_tangent_plane(i as f64 / (ALBEDO_ENTRIES - 1) as f64) as f32)
            .collect()
    });
    table.to_vec()
}

/// What the prefiltered light `P(R)` is divided by, so that it reads as the mean light
/// over the part of the lobe above the tangent plane: `1 - w (1 - share)`, `share` the
/// lobe's share above the tangent plane at `n . R` ([`share_above_table`]) and `w =
/// max(n_z, 0)` where the map's lower hemisphere is black (a ground plane or a height
/// field hides it), 0 elsewhere.
///
/// The split sum's lobe about `R` is the `n = v = R` case; nearer grazing it reaches below
/// the tangent plane, which the surface never reflects. On a floor the part below is the
/// black lower hemisphere, so `P(R)` is `share` times the mean over the rest: a Principled
/// floor of roughness 1 seen at `n . v = 0.16` (`glossy.py`) kept half of Cycles'
/// specular layer. On a wall the part below its tangent plane is sky as much as the part
/// above is, and `P(R)` is that mean already: hence the weight `n_z`.
pub fn below_tangent_divisor(share_above: &[f32], n_dot_r: f64, normal_z: f64, sky_only: bool) -> f64 {
    if !sky_only {
        return 1.0;
    }
    let w = normal_z.clamp(0.0, 1.0);
    1.0 - w * (1.0 - albedo_lookup(share_above, n_dot_r).max(MIN_SHARE_ABOVE))
}

/// The least share [`below_tangent_divisor`] divides by: a lobe about a grazing `R`
/// keeps about half of itself above the tangent plane.
const MIN_SHARE_ABOVE: f64 = 0.25;

/// Linear interpolation of an [`albedo_table`] at `n . v = mu`.
pub fn albedo_lookup(table: &[f32], mu: f64) -> f64 {
    let x = mu.clamp(0.0, 1.0) * (table.len() - 1) as f64;
    let i = (x.floor() as usize).min(table.len() - 2);
    let t = x - i as f64;
    f64::from(table[i]) * (1.0 - t) + f64::from(table[i + 1]) * t
}

/// Height of the coarsest level a map is reduced to.
const MIN_HEIGHT: usize = 4;

/// The prefiltered map has at least this many texels per lobe half-width where the map
/// is fine enough, so that reading it bilinearly keeps the lobe's own detail.
const OUTPUT_TEXELS_PER_HALF_WIDTH: f64 = 2.0;

/// A lobe whose half-width is below this many texels of the map reads the map itself:
/// bilinear reading already spreads a texel that far.
const MIRROR_TEXELS: f64 = 0.5;

/// The lobe's core, out to [`CORE_HALF_WIDTHS`], is integrated over a map with at least
/// this many texels per half-width (its texels are box-filtered, so a coarser input only
/// blurs the lobe by a fraction of a texel).
const INPUT_TEXELS_PER_HALF_WIDTH: f64 = 2.0;

/// The core's reach, in lobe half-widths; between 2/3 of it and all of it, the core
/// hands over to the tail smoothly.
const CORE_HALF_WIDTHS: f64 = 3.0;

/// The tail, from 2/3 of the core's reach to the window's edge, is integrated over a map
/// with at least this many texels per half-width, where it is as smooth.
const TAIL_TEXELS_PER_HALF_WIDTH: f64 = 1.0;

/// The convolution window, in lobe half-widths: the GGX lobe keeps 97 % of its mass
/// within it (its tail beyond falls as `theta^-4`; the window's weights are
/// renormalised), the Phong lobe all of it.
const WINDOW_HALF_WIDTHS: f64 = 12.0;

/// The box-filtered reductions of a map, each half the size of the one before, texels
/// averaged by solid angle: the inputs of the prefiltering, each as fine as its lobe
/// needs.
pub struct MapLevels {
    levels: Vec<Arc<EnvironmentMap>>,
    /// Each level's colour channels apart, made when a convolution first reads the level
    /// and shared by every lobe's.
    planes: Vec<Arc<OnceLock<Planes>>>,
}

impl MapLevels {
    /// `map` with its lower hemisphere black when `sky_only` (the ground plane hides it
    /// from every receiver above the plane), and its reductions.
    pub fn new(map: &EnvironmentMap, strength: f32, sky_only: bool) -> Self {
        let mut base = map.clone();
        for (i, t) in base.texels.iter_mut().enumerate() {
            let row = i / map.width;
            let below = (row as f64 + 0.5) / map.height as f64 > 0.5;
            *t = if sky_only && below { [0.0; 3] } else { t.map(|c| c * strength) };
        }
        let mut levels = vec![Arc::new(base)];
        loop {
            let last = levels.last().expect("one level at least");
            if last.height / 2 < MIN_HEIGHT || last.width % 2 != 0 || last.height % 2 != 0 {
                break;
            }
            let next = reduce(last);
            levels.push(Arc::new(next));
        }
        let planes = levels.iter().map(|_| Arc::new(OnceLock::new())).collect();
        Self { levels, planes }
    }

    /// The map prefiltered with `lobe`, its texels computed when first read
    /// ([`Prefiltered::prepare`]).
    pub fn prefilter(&self, lobe: SharpLobe) -> Prefiltered {
        let s = lobe.half_width();
        let texel = |m: &EnvironmentMap| PI / m.height as f64;
        let coarsest_within = |texels_per_half_width: f64| {
            (0..self.levels.len()).rev().find(|&l| texel(&self.levels[l]) * texels_per_half_width <= s).unwrap_or(0)
        };
        let finest = &self.levels[0];
        if texel(finest) * MIRROR_TEXELS > s {
            return Prefiltered::new(finest.width, finest.height, Source::Map(finest.clone()));
        }
        let output = &self.levels[coarsest_within(OUTPUT_TEXELS_PER_HALF_WIDTH)];
        let parts = [
            (coarsest_within(INPUT_TEXELS_PER_HALF_WIDTH), CORE_HALF_WIDTHS * s, Fade::Out),
            (coarsest_within(TAIL_TEXELS_PER_HALF_WIDTH), WINDOW_HALF_WIDTHS * s, Fade::In),
        ]
        .map(|(level, reach, fade)| {
            Part::new(self.levels[level].clone(), self.planes[level].clone(), reach.min(PI), fade)
        });
        let handover = [2.0 / 3.0 * CORE_HALF_WIDTHS * s, CORE_HALF_WIDTHS * s].map(|a| a.min(PI).cos());
        let convolution = Convolution::new(parts, handover, lobe, output.width, output.height);
        Prefiltered::new(output.width, output.height, Source::Convolution(Box::new(convolution)))
    }
}

/// The core's share of a direction at `cos theta = z` from the lobe's axis: 1 up to the
/// handover's first cosine, 0 beyond its second, a smoothstep in `cos theta` between. A
/// lobe whose core reaches round the sphere (GGX from `alpha` 0.8 on, whose half-width
/// is over 120 degrees) has both cosines at -1, and the core takes every direction: the
/// ratio between them, 0 / 0 at the antipode, once made a texel's weights NaN and its
/// table empty, and the map of such a lobe came out as the raw map's texels.
fn core_fade([fade_start, fade_end]: [f64; 2], z: f64) -> f64 {
    if fade_start - fade_end <= 0.0 {
        return if z >= fade_end { 1.0 } else { 0.0 };
    }
    let t = ((fade_start - z) / (fade_start - fade_end)).clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// One reduction: each texel the solid-angle-weighted mean of the 2 x 2 it covers.
fn reduce(map: &EnvironmentMap) -> EnvironmentMap {
    let (width, height) = (map.width / 2, map.height / 2);
    let mut texels = vec![[0.0f32; 3]; width * height];
    for row in 0..height {
        let (w0, w1) = (map.texel_solid_angle(2 * row), map.texel_solid_angle(2 * row + 1));
        for column in 0..width {
            let mut sum = [0.0f64; 3];
            for (r, w) in [(2 * row, w0), (2 * row + 1, w1)] {
                for c in [2 * column, 2 * column + 1] {
                    let t = map.texels[r * map.width + c];
                    for k in 0..3 {
                        sum[k] += w * f64::from(t[k]);
                    }
                }
            }
            texels[row * width + column] = sum.map(|v| (v / (2.0 * (w0 + w1))) as f32);
        }
    }
    EnvironmentMap { file: map.file.clone(), width, height, texels }
}

/// One part of a convolution: the map it reads (and its colour channels apart, made when
/// first read), with its texel centres' (sin, cos) of polar angle and azimuth
/// (`equirectangular_to_direction`) and solid angles, how far from the axis it reaches,
/// and whether it fades out or in across the hand-over.
struct Part {
    map: Arc<EnvironmentMap>,
    planes: Arc<OnceLock<Planes>>,
    rows: Vec<(f64, f64)>,
    columns: Vec<(f64, f64)>,
    solid_angles: Vec<f64>,
    reach: f64,
    fade: Fade,
}

#[derive(Clone, Copy)]
enum Fade {
    Out,
    In,
}

fn polar(row: usize, height: usize) -> f64 {
    PI * (row as f64 + 0.5) / height as f64
}

fn azimuth(column: usize, width: usize) -> f64 {
    PI - 2.0 * PI * (column as f64 + 0.5) / width as f64
}

fn direction((sin_t, cos_t): (f64, f64), (sin_p, cos_p): (f64, f64)) -> [f64; 3] {
    [sin_t * cos_p, sin_t * sin_p, cos_t]
}

impl Part {
    fn new(map: Arc<EnvironmentMap>, planes: Arc<OnceLock<Planes>>, reach: f64, fade: Fade) -> Self {
        Self {
            planes,
            rows: (0..map.height).map(|r| polar(r, map.height).sin_cos()).collect(),
            columns: (0..map.width).map(|c| azimuth(c, map.width).sin_cos()).collect(),
            solid_angles: (0..map.height).map(|r| map.texel_solid_angle(r)).collect(),
            map,
            reach,
            fade,
        }
    }
}

impl Part {
    fn planes(&self) -> &Planes {
        self.planes.get_or_init(|| Planes::new(&self.map))
    }
}

/// A map's colour channels apart, row-major, each followed by [`SUM_LANES`] zeros: the
/// tables' weighted sums read a run of each channel's row as one slice, in whole lanes
/// (the weights padded with zeros) even where the run ends at the map's last texel.
struct Planes {
    channels: [Vec<f32>; 3],
    width: usize,
}

impl Planes {
    fn new(map: &EnvironmentMap) -> Self {
        let padding = std::iter::repeat_n(0.0, SUM_LANES);
        let channels = [0, 1, 2].map(|k| map.texels.iter().map(|t| t[k]).chain(padding.clone()).collect());
        Self { channels, width: map.width }
    }

    /// Columns `start..start + len` of row `row`, each channel; `len` may reach
    /// [`SUM_LANES`] - 1 past the row's end (into the next row, or the padding).
    fn run(&self, row: usize, start: usize, len: usize) -> [&[f32]; 3] {
        self.channels.each_ref().map(|channel| &channel[row * self.width + start..][..len])
    }
}

/// What a prefiltered map's texels are.
enum Source {
    /// The map itself, for a lobe narrower than half its texel.
    Map(Arc<EnvironmentMap>),
    /// The lobe's convolution of the core part and the tail part, each over its reach
    /// about the texel's centre, the weights renormalised. The core fades out and the
    /// tail in between the cosines `handover` (a smoothstep in `cos theta`), so each
    /// direction's weights sum to the lobe's.
    Convolution(Box<Convolution>),
}

/// A convolution's weights, tabulated per output row.
///
/// A texel's weights depend on its column only through the azimuth between its centre
/// and the input texels' (a turn about Z), so every texel of an output row whose centre
/// sits at the same fraction of an input column has the same weights, shifted by whole
/// input columns. Output columns `phase + m P` do, with `P` the least multiple of
/// `width / gcd(width, W)` over the parts' input widths `W` (1 where a part is as wide
/// as the output, 2 for the tail's half-width level). One table per row and phase,
/// computed when a texel of it is first read, turns a texel into a weighted sum of
/// texels: the lobe is evaluated once per table instead of once per texel (the cones
/// sample's 128 x 64 lobe map: about 1,250 lobe evaluations per texel before).
struct Convolution {
    parts: [Part; 2],
    handover: [f64; 2],
    lobe: SharpLobe,
    /// `P` above.
    phases: usize,
    /// `tables[row * phases + phase]`.
    tables: Vec<OnceLock<WeightTable>>,
}

/// The weights of the texels of one output row and phase: per input row a run of
/// columns, placed relative to the column that holds the texel's centre in that part's
/// map, the weights divided by their sum over both parts.
struct WeightTable {
    runs: Vec<Run>,
    weights: Vec<f32>,
}

/// `weights[first..first + len]` apply to the part's row `row`, at columns `start..start
/// + len` from the one under the texel's centre, wrapping around the map (never more
/// than once: a run is at most a row); zeros follow them up to whole [`SUM_LANES`].
struct Run {
    part: usize,
    row: usize,
    start: isize,
    first: usize,
    len: usize,
}

/// Partial sums per channel in [`Convolution::weighted_sum`].
const SUM_LANES: usize = 8;

/// Adds `sum of weights[i] rows[k][i]` to channel `k`: whole lanes to `lanes`, the rest
/// to `rest`. A function rather than a closure, so that it is inlined into each build of
/// its caller, with that build's registers.
#[inline(always)]
fn add_run(lanes: &mut [[f32; SUM_LANES]; 3], rest: &mut [f32; 3], weights: &[f32], rows: [&[f32]; 3]) {
    let whole = weights.len() / SUM_LANES * SUM_LANES;
    for (b, w) in weights[..whole].chunks_exact(SUM_LANES).enumerate() {
        for (k, row) in rows.iter().enumerate() {
            let v = &row[b * SUM_LANES..][..SUM_LANES];
            for i in 0..SUM_LANES {
                lanes[k][i] += w[i] * v[i];
            }
        }
    }
    for (k, row) in rows.iter().enumerate() {
        for i in whole..weights.len() {
            rest[k] += weights[i] * row[i];
        }
    }
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// The column of a `map_width` map under the centre of column `column` of a `width`
/// map: `floor((column + 1/2) map_width / width)`, in integers so that every column of
/// a phase agrees with its table.
fn column_under(column: usize, width: usize, map_width: usize) -> usize {
    (2 * column + 1) * map_width / (2 * width)
}

impl Convolution {
    fn new(parts: [Part; 2], handover: [f64; 2], lobe: SharpLobe, width: usize, height: usize) -> Self {
        let phases = parts.iter().fold(1, |p, part| {
            let own = width / gcd(width, part.map.width);
            p / gcd(p, own) * own
        });
        let tables = (0..height * phases).map(|_| OnceLock::new()).collect();
        Self { parts, handover, lobe, phases, tables }
    }

    /// Texel (column, row) of a `width` x `height` map.
    fn texel(&self, width: usize, height: usize, column: usize, row: usize) -> [f32; 3] {
        let phase = column % self.phases;
        let table = self.tables[row * self.phases + phase].get_or_init(|| self.table(width, height, phase, row));
        if table.runs.is_empty() {
            let axis = direction(polar(row, height).sin_cos(), azimuth(column, width).sin_cos());
            return self.parts[0].map.lookup(axis);
        }
        #[cfg(target_arch = "x86_64")]
        if *crate::x86::AVX2 {
            // SAFETY: the processor has AVX2.
            return unsafe { self.weighted_sum_avx2(table, width, column) };
        }
        self.weighted_sum(table, width, column)
    }

    /// [`Self::weighted_sum`] compiled for AVX2, its lanes in those registers: the same
    /// operations in the same order, so the same bits.
    ///
    /// # Safety
    /// The processor has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn weighted_sum_avx2(&self, table: &WeightTable, width: usize, column: usize) -> [f32; 3] {
        self.weighted_sum(table, width, column)
    }

    /// `sum of weights[i] texel[i]` over the runs of `table` placed for column `column`
    /// of a `width`-wide map, per colour channel, in eight f32 partial sums per channel
    /// (about 150 terms each for the cones sample's lobe, so f32 keeps the sum to about
    /// 1e-7 of it). Each run is read in one piece, or two where it wraps: up to its row's
    /// end, then from its start. Plain multiplies and adds (a fused multiply-add gained
    /// nothing here), so every build gives the same bits.
    #[inline(always)]
    fn weighted_sum(&self, table: &WeightTable, width: usize, column: usize) -> [f32; 3] {
        let under = self.parts.each_ref().map(|part| column_under(column, width, part.map.width) as isize);
        let planes = self.parts.each_ref().map(Part::planes);
        let mut lanes = [[0.0f32; SUM_LANES]; 3];
        let mut rest = [0.0f32; 3];
        for run in &table.runs {
            let part_width = self.parts[run.part].map.width;
            // In (-width, 2 width): a run starts within a map's width of the centre.
            let start = under[run.part] + run.start;
            let start = if start < 0 {
                start + part_width as isize
            } else if start >= part_width as isize {
                start - part_width as isize
            } else {
                start
            } as usize;
            let planes = planes[run.part];
            if start + run.len <= part_width {
                // In whole lanes: the padding's weights are zero.
                let padded = run.len.next_multiple_of(SUM_LANES);
                let weights = &table.weights[run.first..][..padded];
                add_run(&mut lanes, &mut rest, weights, planes.run(run.row, start, padded));
            } else {
                let weights = &table.weights[run.first..][..run.len];
                let before_wrap = part_width - start;
                add_run(&mut lanes, &mut rest, &weights[..before_wrap], planes.run(run.row, start, before_wrap));
                add_run(&mut lanes, &mut rest, &weights[before_wrap..], planes.run(run.row, 0, run.len - before_wrap));
            }
        }
        [0, 1, 2].map(|k| lanes[k].iter().sum::<f32>() + rest[k])
    }

    /// The table of output row `row` and phase `phase`: the weights of the texel at
    /// column `phase`, the reach of each part about its axis.
    fn table(&self, width: usize, height: usize, phase: usize, row: usize) -> WeightTable {
        let fade_out = |z: f64| core_fade(self.handover, z);
        let theta = polar(row, height);
        let axis = direction(theta.sin_cos(), azimuth(phase, width).sin_cos());
        let (mut runs, mut weights, mut total) = (Vec::new(), Vec::<f64>::new(), 0.0f64);
        for (p, part) in self.parts.iter().enumerate() {
            let map = &part.map;
            let margin = part.reach + PI / map.height as f64;
            let cos_reach = part.reach.cos();
            let under = column_under(phase, width, map.width) as isize;
            for r in (0..map.height).filter(|&r| (polar(r, map.height) - theta).abs() <= margin) {
                // The columns within reach at this row: all of them near a pole.
                let reach = (margin / part.rows[r].0.max(1e-9) / (2.0 * PI) * map.width as f64).ceil() as isize + 1;
                let offsets = if 2 * reach + 1 >= map.width as isize {
                    -under..map.width as isize - under
                } else {
                    -reach..reach + 1
                };
                let row_weights: Vec<f64> = offsets
                    .clone()
                    .map(|offset| {
                        let c = (under + offset).rem_euclid(map.width as isize) as usize;
                        let z = dot(axis, direction(part.rows[r], part.columns[c]));
                        if z < cos_reach {
                            return 0.0;
                        }
                        let share = match part.fade {
                            Fade::Out => fade_out(z),
                            Fade::In => 1.0 - fade_out(z),
                        };
                        if share <= 0.0 {
                            return 0.0;
                        }
                        share * self.lobe.value(z) * part.solid_angles[r]
                    })
                    .collect();
                let Some(first) = row_weights.iter().position(|&w| w > 0.0) else { continue };
                let last = row_weights.iter().rposition(|&w| w > 0.0).expect("a first one");
                let used = &row_weights[first..=last];
                total += used.iter().sum::<f64>();
                let (start, len) = (offsets.start + first as isize, used.len());
                runs.push(Run { part: p, row: r, start, first: weights.len(), len });
                weights.extend_from_slice(used);
                weights.resize(weights.len() + len.next_multiple_of(SUM_LANES) - len, 0.0);
            }
        }
        if !(total > 0.0) {
            return WeightTable { runs: Vec::new(), weights: Vec::new() };
        }
        WeightTable { runs, weights: weights.iter().map(|w| (w / total) as f32).collect() }
    }
}

/// An environment map prefiltered with one lobe: `P(R) = integral L(w) lobe(R . w) dw`,
/// an equirectangular map in the orientation of [`EnvironmentMap`]. A texel is computed
/// the first time it is read, or for the directions a frame reads ([`Self::prepare`]):
/// a frame reads a few thousand of a map's texels.
pub struct Prefiltered {
    pub width: usize,
    pub height: usize,
    source: Source,
    texels: Vec<OnceLock<[f32; 3]>>,
}

impl std::fmt::Debug for Prefiltered {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Prefiltered({}x{})", self.width, self.height)
    }
}

impl Prefiltered {
    fn new(width: usize, height: usize, source: Source) -> Self {
        let texels = match source {
            Source::Map(_) => Vec::new(),
            Source::Convolution(_) => (0..width * height).map(|_| OnceLock::new()).collect(),
        };
        Self { width, height, source, texels }
    }

    /// Texel (column, row).
    #[inline(always)]
    pub fn texel(&self, column: usize, row: usize) -> [f32; 3] {
        match &self.source {
            Source::Map(map) => map.texels[row * map.width + column],
            Source::Convolution(convolution) => *self.texels[row * self.width + column]
                .get_or_init(|| convolution.texel(self.width, self.height, column, row)),
        }
    }

    /// `P(R)`, bilinearly.
    #[inline(always)]
    pub fn lookup(&self, direction: [f64; 3]) -> [f32; 3] {
        self.lookup_at(lookup_coordinates(direction))
    }

    /// `P` at the lookup coordinates of `R` ([`lookup_coordinates`]), bilinearly.
    ///
    /// Once a frame has computed the texels it reads, each lookup checks its four texels
    /// together and blends them, the computing path out of line: where each texel was
    /// read through its own `get_or_init`.
    #[inline(always)]
    pub fn lookup_at(&self, coordinates: [f64; 2]) -> [f32; 3] {
        match &self.source {
            Source::Map(map) => map.lookup_at(coordinates),
            Source::Convolution(_) => {
                let taps = BilinearTaps::at(self.width, self.height, coordinates);
                let ([c0, c1], [r0, r1]) = (taps.columns, taps.rows);
                let at = |column: usize, row: usize| self.texels[row * self.width + column].get();
                match [at(c0, r0), at(c1, r0), at(c0, r1), at(c1, r1)] {
                    [Some(a), Some(b), Some(c), Some(d)] => taps.blend([*a, *b, *c, *d]),
                    _ => self.lookup_computing(taps),
                }
            }
        }
    }

    /// [`Self::lookup_at`] where a texel it blends is still to be computed.
    #[cold]
    #[inline(never)]
    fn lookup_computing(&self, taps: BilinearTaps) -> [f32; 3] {
        taps.read(|column, row| self.texel(column, row))
    }

    /// Computes the texels that a bilinear read along `direction` blends, and, where the
    /// read falls within a thousandth of a texel of the next one, that one too (an
    /// executor whose rounding differs may pick it).
    pub fn prepare(&self, direction: [f64; 3]) {
        const MARGIN: f32 = 1e-3;
        if self.texels.is_empty() {
            return;
        }
        let taps = BilinearTaps::new(self.width, self.height, direction);
        let [c0, c1] = taps.columns;
        let [r0, r1] = taps.rows;
        let column_before = (taps.tx < MARGIN).then(|| (c0 + self.width - 1) % self.width);
        let column_after = (taps.tx > 1.0 - MARGIN).then(|| (c1 + 1) % self.width);
        let row_before = (taps.ty < MARGIN && r0 > 0).then(|| r0 - 1);
        let row_after = (taps.ty > 1.0 - MARGIN && r1 + 1 < self.height).then(|| r1 + 1);
        let columns = [Some(c0), Some(c1), column_before, column_after].into_iter().flatten();
        for column in columns {
            for row in [Some(r0), Some(r1), row_before, row_after].into_iter().flatten() {
                self.texel(column, row);
            }
        }
    }

    /// Every texel computed so far, row by row, zero where none was: what a GPU program
    /// uploads after [`Self::prepare`].
    pub fn computed_texels(&self) -> Vec<[f32; 3]> {
        match &self.source {
            Source::Map(map) => map.texels.clone(),
            Source::Convolution(_) => self.texels.iter().map(|t| t.get().copied().unwrap_or([0.0; 3])).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The split sum's known bias on a rough lobe (docs/method/materials.md): a floor's
    /// reflection of a graded sky (radiance `1 + 3 z^2`, with a warm patch) read as the
    /// lobe's albedo times the lobe-weighted mean of the sky above the floor (what `P /
    /// below_tangent_divisor` reads), against a quadrature of GGX's BRDF times the cosine.
    /// The true lobe weighs the zenith through its masking, which a lobe symmetric about
    /// `R` cannot: 10 to 17 % too dark for alpha 0.7 to 1. Prints the table; fails if the
    /// bias leaves that range, so that a change to the lobe or its albedo shows here.
    #[test]
    fn a_rough_lobes_split_sum_reads_a_graded_sky_too_dark() {
        let sky = |w: [f64; 3]| 1.0 + 3.0 * w[2] * w[2] + 4.0 * dot(w, [0.6, 0.0, 0.8]).max(0.0).powi(8);
        let (rings, sectors) = (180, 360);
        let mut directions = Vec::with_capacity(rings * sectors);
        for i in 0..rings {
            let theta = FRAC_PI_2 * (i as f64 + 0.5) / rings as f64;
            let solid_angle = theta.sin() * (FRAC_PI_2 / rings as f64) * (2.0 * PI / sectors as f64);
            for j in 0..sectors {
                let phi = 2.0 * PI * (j as f64 + 0.5) / sectors as f64;
                let w = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
                directions.push((w, solid_angle, sky(w)));
            }
        }
        for alpha in [0.7, 0.81, 0.9, 1.0] {
            let lobe = SharpLobe::Ggx { alpha };
            for mu in [0.15f64, 0.3, 0.5, 0.8] {
                let v = [-(1.0 - mu * mu).sqrt(), 0.0, mu];
                let reflected = [-v[0], 0.0, v[2]];
                let truth: f64 = directions
                    .iter()
                    .map(|&(w, d_omega, radiance)| radiance * ggx_lit(alpha, 1.0, mu, w[2], dot(v, w)) * d_omega)
                    .sum();
                let (mut light, mut mass) = (0.0, 0.0);
                for &(w, d_omega, radiance) in &directions {
                    let weight = lobe.value(dot(reflected, w)) * d_omega;
                    light += radiance * weight;
                    mass += weight;
                }
                let bias = lobe.albedo(mu) * light / mass / truth - 1.0;
                println!("alpha {alpha} n . v {mu}: {bias:+.3}");
                assert!((-0.18..=-0.09).contains(&bias), "alpha {alpha}, n . v {mu}: {bias}");
            }
        }
    }
    use crate::scene::light::direction_to_equirectangular;

    /// A sky of the kind the glossy term must mirror: a gradient, coloured patches and a
    /// window 20 times brighter, in a 512 x 256 map.
    fn featured_sky() -> EnvironmentMap {
        let (width, height) = (512, 256);
        let texels = (0..width * height)
            .map(|i| {
                let (u, v) = ((i % width) as f64 / width as f64, 1.0 - (i / width) as f64 / height as f64);
                let mut t = [0.3 + 0.4 * v, 0.4 + 0.3 * v, 0.6 + 0.3 * v];
                if (0.1..0.2).contains(&u) && (0.55..0.65).contains(&v) {
                    t = [2.0, 0.2, 0.1];
                }
                if (0.5..0.55).contains(&u) && (0.6..0.75).contains(&v) {
                    t = [20.0, 20.0, 18.0];
                }
                t.map(|c| c as f32)
            })
            .collect();
        EnvironmentMap { file: "featured sky".into(), width, height, texels }
    }

    /// `integral L lobe(R . w) dw` over every texel centre of `map`, normalised by the
    /// lobe's own sum (the brute force the prefiltered maps are checked against).
    fn brute_force(map: &EnvironmentMap, lobe: SharpLobe, axis: [f64; 3]) -> [f64; 3] {
        let (mut sum, mut weights) = ([0.0f64; 3], 0.0);
        for row in 0..map.height {
            let omega = map.texel_solid_angle(row);
            for column in 0..map.width {
                let d = crate::scene::light::equirectangular_to_direction(
                    (column as f64 + 0.5) / map.width as f64,
                    1.0 - (row as f64 + 0.5) / map.height as f64,
                );
                let w = lobe.value(dot(axis, d)) * omega;
                for k in 0..3 {
                    sum[k] += w * f64::from(map.texels[row * map.width + column][k]);
                }
                weights += w;
            }
        }
        sum.map(|s| s / weights)
    }

    /// Texel (column, row) of a `width` x `height` map of `lobe`'s convolution of `parts`,
    /// summed texel by texel with the lobe evaluated at each: the oracle of the tables.
    fn convolved_texel(
        parts: &[Part; 2],
        handover: [f64; 2],
        lobe: SharpLobe,
        width: usize,
        height: usize,
        column: usize,
        row: usize,
    ) -> [f32; 3] {
        let fade_out = |z: f64| super::core_fade(handover, z);
        let theta = polar(row, height);
        let axis = direction(theta.sin_cos(), azimuth(column, width).sin_cos());
        let (mut sum, mut weights) = ([0.0f64; 3], 0.0f64);
        for part in parts {
            let map = &part.map;
            let margin = part.reach + PI / map.height as f64;
            let cos_reach = part.reach.cos();
            let centre = (column as f64 + 0.5) / width as f64 * map.width as f64;
            for r in (0..map.height).filter(|&r| (polar(r, map.height) - theta).abs() <= margin) {
                // The columns within reach at this row: all of them near a pole.
                let reach = (margin / part.rows[r].0.max(1e-9) / (2.0 * PI) * map.width as f64).ceil() as usize + 1;
                let (first, count) = if 2 * reach + 1 >= map.width {
                    (0, map.width)
                } else {
                    (centre as usize + map.width - reach, 2 * reach + 1)
                };
                for c in (first..first + count).map(|c| c % map.width) {
                    let z = dot(axis, direction(part.rows[r], part.columns[c]));
                    if z < cos_reach {
                        continue;
                    }
                    let share = match part.fade {
                        Fade::Out => fade_out(z),
                        Fade::In => 1.0 - fade_out(z),
                    };
                    if share <= 0.0 {
                        continue;
                    }
                    let w = share * lobe.value(z) * part.solid_angles[r];
                    let t = map.texels[r * map.width + c];
                    for k in 0..3 {
                        sum[k] += w * f64::from(t[k]);
                    }
                    weights += w;
                }
            }
        }
        if weights > 0.0 {
            sum.map(|v| (v / weights) as f32)
        } else {
            parts[0].map.lookup(axis)
        }
    }

    /// Every texel of a few rows (poles, mid-latitudes, the equator) read from the
    /// tables against the oracle, for maps whose reductions are as wide as the output,
    /// half as wide, and stop early (a width with an odd half). Measured: within 5e-7 of
    /// the texel's value (the weights and the sums are f32), and 1.5e-5 where a
    /// texel lies on the window's edge, which cuts GGX's tail where it is not zero: two
    /// columns' cosines to that texel, equal but for rounding, fall on either side of it.
    #[test]
    fn tabulated_texels_match_the_direct_sum() {
        let odd = {
            let sky = featured_sky();
            let (width, height) = (360, 180);
            let texels = (0..width * height)
                .map(|i| {
                    let d = crate::scene::light::equirectangular_to_direction(
                        ((i % width) as f64 + 0.5) / width as f64,
                        1.0 - ((i / width) as f64 + 0.5) / height as f64,
                    );
                    sky.lookup(d)
                })
                .collect();
            EnvironmentMap { file: "odd sky".into(), width, height, texels }
        };
        for map in [featured_sky(), odd] {
            let levels = MapLevels::new(&map, 1.0, true);
            for lobe in [
                SharpLobe::Ggx { alpha: ggx_alpha(7.5) },
                SharpLobe::Ggx { alpha: ggx_alpha(300.0) },
                SharpLobe::Phong { exponent: 61.0 },
            ] {
                let prefiltered = levels.prefilter(lobe);
                let Source::Convolution(convolution) = &prefiltered.source else { panic!("{lobe:?} convolves") };
                let (width, height) = (prefiltered.width, prefiltered.height);
                let mut worst = 0.0f64;
                for row in [0, 1, height / 5, height / 2 - 1, height / 2, height - 1] {
                    for column in 0..width {
                        let direct =
                            convolved_texel(&convolution.parts, convolution.handover, lobe, width, height, column, row);
                        let read = prefiltered.texel(column, row);
                        for k in 0..3 {
                            let scale = f64::from(direct[k]).abs().max(1e-3);
                            worst = worst.max(f64::from(read[k] - direct[k]).abs() / scale);
                        }
                    }
                }
                eprintln!(
                    "{} {lobe:?}: {width}x{height}, {} phases, worst {worst:.2e}",
                    map.file.display(),
                    convolution.phases
                );
                assert!(worst < 5e-5, "{lobe:?}: {worst}");
            }
        }
    }

    /// The AVX2 build of the weighted sums gives the portable build's bits, on runs that
    /// wrap and runs that do not.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn both_builds_of_the_weighted_sums_agree() {
        if !*crate::x86::AVX2 {
            eprintln!("this processor has no AVX2: one build only");
            return;
        }
        let levels = MapLevels::new(&featured_sky(), 1.0, false);
        let prefiltered = levels.prefilter(SharpLobe::Phong { exponent: 61.0 });
        let Source::Convolution(convolution) = &prefiltered.source else { panic!("Phong 61 convolves") };
        let (width, height) = (prefiltered.width, prefiltered.height);
        for row in [0, height / 3, height / 2] {
            for column in [0, 1, width / 2, width - 1] {
                let phase = column % convolution.phases;
                let table = convolution.table(width, height, phase, row);
                let portable = convolution.weighted_sum(&table, width, column);
                // SAFETY: the processor has AVX2 (checked above).
                let avx2 = unsafe { convolution.weighted_sum_avx2(&table, width, column) };
                assert_eq!(portable.map(f32::to_bits), avx2.map(f32::to_bits), "row {row}, column {column}");
            }
        }
    }

    fn directions(count: usize) -> Vec<[f64; 3]> {
        let golden = PI * (3.0 - 5f64.sqrt());
        (0..count)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
                let s = (1.0 - z * z).sqrt();
                [s * (golden * i as f64).cos(), s * (golden * i as f64).sin(), z]
            })
            .collect()
    }

    #[test]
    fn lobes_integrate_to_one() {
        for lobe in [SharpLobe::Ggx { alpha: 0.3 }, SharpLobe::Ggx { alpha: 0.05 }, SharpLobe::Phong { exponent: 50.0 }]
        {
            // In cos theta, with nodes packed towards the axis where the lobe lives.
            let steps = 200_000;
            let integral: f64 = (0..steps)
                .map(|i| {
                    let t = (i as f64 + 0.5) / steps as f64;
                    let z = 1.0 - 2.0 * t * t;
                    lobe.value(z) * 2.0 * PI * 4.0 * t / steps as f64
                })
                .sum();
            assert!((integral - 1.0).abs() < 2e-3, "{lobe:?}: {integral}");
        }
    }

    /// The prefiltered maps against the brute-force integral of the lobe over the map,
    /// along 200 directions, for lobes from rough to near-mirror. Measured errors,
    /// relative to the larger of the exact value and the map's mean radiance (a window
    /// 20 times brighter than the sky is in the map): worst 1.7 % to 3.8 %, mean 0.1 % to
    /// 0.5 %. The worst are where a window's edge crosses the lobe's core, read from a
    /// map with two texels per half-width.
    #[test]
    fn prefiltered_lookups_match_brute_force() {
        let map = featured_sky();
        let mean = map.texels.iter().map(|t| f64::from(t[1])).sum::<f64>() / map.texels.len() as f64;
        let levels = MapLevels::new(&map, 1.0, false);
        for (lobe, tolerance) in [
            (SharpLobe::Ggx { alpha: ggx_alpha(7.5) }, 0.03),
            (SharpLobe::Ggx { alpha: ggx_alpha(60.0) }, 0.04),
            (SharpLobe::Ggx { alpha: ggx_alpha(300.0) }, 0.04),
            (SharpLobe::Phong { exponent: 60.0 }, 0.05),
            (SharpLobe::Phong { exponent: 300.0 }, 0.04),
        ] {
            let prefiltered = levels.prefilter(lobe);
            let (mut worst, mut total) = (0.0f64, 0.0);
            for axis in directions(200) {
                let exact = brute_force(&map, lobe, axis);
                let read = prefiltered.lookup(axis);
                for k in 0..3 {
                    let error = (f64::from(read[k]) - exact[k]).abs() / exact[k].max(mean);
                    worst = worst.max(error);
                    total += error;
                }
            }
            eprintln!(
                "{lobe:?}: {}x{}, worst {worst:.4}, mean {:.4}",
                prefiltered.width,
                prefiltered.height,
                total / 600.0
            );
            assert!(worst < tolerance, "{lobe:?}: worst {worst}");
        }
    }

    /// A lookup whose texels are already computed (one check for the four) reads the same
    /// bits as the lookup that computed them and as a blend of [`Prefiltered::texel`],
    /// including where two of the four are computed and two are not.
    #[test]
    fn a_lookup_reads_the_same_whether_or_not_its_texels_were_computed() {
        let map = featured_sky();
        let levels = MapLevels::new(&map, 1.0, false);
        let lobe = SharpLobe::Ggx { alpha: ggx_alpha(60.0) };
        let (computing, computed) = (levels.prefilter(lobe), levels.prefilter(lobe));
        for axis in directions(300) {
            let coordinates = crate::scene::light::lookup_coordinates(axis);
            let taps = BilinearTaps::at(computed.width, computed.height, coordinates);
            computed.texel(taps.columns[0], taps.rows[0]);
            computed.texel(taps.columns[1], taps.rows[1]);
            let first = computed.lookup_at(coordinates);
            let by_texels = taps.read(|column, row| computed.texel(column, row));
            assert_eq!(first, by_texels, "{axis:?}");
            assert_eq!(computed.lookup_at(coordinates), by_texels, "{axis:?}");
            assert_eq!(computing.lookup_at(coordinates), by_texels, "{axis:?}");
        }
    }

    /// A lobe narrower than half a texel reads the map itself.
    #[test]
    fn a_mirror_reads_the_map() {
        let map = featured_sky();
        let levels = MapLevels::new(&map, 2.0, false);
        let mirror = levels.prefilter(SharpLobe::Ggx { alpha: ggx_alpha(1e6) });
        assert_eq!((mirror.width, mirror.height), (map.width, map.height));
        let d = crate::scene::light::equirectangular_to_direction(0.525, 0.7);
        assert_eq!(mirror.lookup(d), map.lookup(d).map(|c| 2.0 * c));
        assert!(direction_to_equirectangular(d)[0] > 0.5);
    }

    /// The Fresnel term against Snell's law and the amplitudes of the s and p waves
    /// (Born and Wolf): a dielectric of IOR 1.5 (reflectance 0.04) and one of 1.33 (water,
    /// 0.02) to 1e-12 at every angle; a metal's (0.9) is Schlick's; each is its reflectance
    /// at normal incidence, and 1 at grazing.
    #[test]
    fn fresnel_matches_the_fresnel_equations() {
        let equations = |eta: f64, c: f64| {
            let sin_t = (1.0 - c * c).sqrt() / eta;
            let cos_t = (1.0 - sin_t * sin_t).sqrt();
            let s = (c - eta * cos_t) / (c + eta * cos_t);
            let p = (eta * c - cos_t) / (eta * c + cos_t);
            0.5 * (s * s + p * p)
        };
        for eta in [1.5f64, 1.33] {
            let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            let fresnel = Fresnel::new(f0);
            for i in 0..=100 {
                let c = i as f64 / 100.0;
                let (got, expected) = (fresnel.at(c), if c > 0.0 { equations(eta, c) } else { 1.0 });
                assert!((got - expected).abs() < 1e-12, "IOR {eta}, cos {c}: {got} against {expected}");
            }
            assert!((fresnel.at(1.0) - f0).abs() < 1e-12);
        }
        let metal = Fresnel::new(0.9);
        for c in [0.0, 0.3, 0.7, 1.0] {
            assert!((metal.at(c) - schlick(0.9, c)).abs() < 1e-15);
        }
        assert_eq!(Fresnel::new(1.0).at(0.4), 1.0);
    }

    /// GGX's directional albedo against an independent integral of `D G2 / (4 n.v)` over
    /// the hemisphere of light directions; Phong's share above the tangent plane is 1
    /// facing it and 1/2 at grazing.
    #[test]
    fn albedos_match_direct_integration() {
        for alpha in [0.05, 0.25, 0.5] {
            for mu in [1.0, 0.7, 0.3, 0.1] {
                let v = [(1.0f64 - mu * mu).sqrt(), 0.0, mu];
                let (rows, columns) = (2000, 400);
                let mut direct = 0.0;
                for i in 0..rows {
                    // l by the angle from the mirror direction is too sharp for a plain grid
                    // at small alpha; integrate over the half vector instead.
                    let theta_h = (i as f64 + 0.5) / rows as f64 * PI / 2.0;
                    for j in 0..columns {
                        let phi = (j as f64 + 0.5) / columns as f64 * 2.0 * PI;
                        let h = [theta_h.sin() * phi.cos(), theta_h.sin() * phi.sin(), theta_h.cos()];
                        let vh = dot(v, h);
                        let l_z = 2.0 * vh * h[2] - v[2];
                        if vh <= 0.0 || l_z <= 0.0 {
                            continue;
                        }
                        let d_omega_h = theta_h.sin() * (PI / 2.0 / rows as f64) * (2.0 * PI / columns as f64);
                        // dw_l = 4 (v . h) dw_h; v . l = 2 (v . h)^2 - 1.
                        direct += ggx_lit(alpha, 1.0, mu, l_z, 2.0 * vh * vh - 1.0) * 4.0 * vh * d_omega_h;
                    }
                }
                let tabulated = SharpLobe::Ggx { alpha }.albedo(mu);
                assert!((tabulated - direct).abs() < 0.01, "alpha {alpha}, mu {mu}: {tabulated} vs {direct}");
            }
        }
        // The BRDF over the light's direction itself, as a sharp light samples it, without
        // and with a Fresnel term.
        for (alpha, mu, f0) in [(0.5, 0.9, 1.0), (0.8, 0.3, 1.0), (0.5, 0.9, 0.04), (0.8, 0.3, 0.04)] {
            let v = [(1.0f64 - mu * mu).sqrt(), 0.0, mu];
            let (rows, columns) = (1000, 1000);
            let mut direct = 0.0;
            for i in 0..rows {
                let z = (i as f64 + 0.5) / rows as f64;
                for j in 0..columns {
                    let phi = (j as f64 + 0.5) / columns as f64 * 2.0 * PI;
                    let s = (1.0 - z * z).sqrt();
                    let w = [s * phi.cos(), s * phi.sin(), z];
                    direct += ggx_lit(alpha, f0, mu, z, dot(v, w)) * 2.0 * PI / (rows * columns) as f64;
                }
            }
            let tabulated = SharpLobe::Ggx { alpha }.fresnel_albedo(mu, f0);
            assert!(
                (tabulated - direct).abs() < 0.01 * f0.max(0.1),
                "alpha {alpha}, mu {mu}, f0 {f0}: {tabulated} vs {direct}"
            );
        }
        let phong = SharpLobe::Phong { exponent: 200.0 };
        assert!((phong.albedo(1.0) - 1.0).abs() < 1e-9);
        assert!((phong.albedo(1e-4) - 0.5).abs() < 0.02, "{}", phong.albedo(1e-4));
    }
}
