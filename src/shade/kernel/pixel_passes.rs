//! The kernel's radiance split into compositing passes, and the visibility terms
//! (docs/design.md, "Compositing passes").
//!
//! The diffuse and specular terms are the very values [`ShadingKernel::shade`] sums (the
//! sharp lights' included), so `diffuse + specular` is its result bit for bit. The
//! visibility terms are the environment's: a sun's or lamp's shadow is in the beauty and the
//! diffuse and specular passes, not in these ratios. The visibility terms are scalar
//! ratios, one per occluder set `x`:
//!
//! ```text
//! visibility_x = lum(exp*(T + V_x + D) . L) / lum(exp*(T + D) . L)
//! ```
//!
//! with `D` the diffuse lobe rotated to the normal, `T` the tangent-plane clamp (what an
//! unoccluded receiver sees), `V_x` the log visibility of the height field, of the
//! sphere blockers, or of both (`combined`), `L` the light's SH vector per colour channel
//! (each dot clamped at 0, as in the beauty) and `lum` Rec. 709 luminance. Log vectors
//! add, so one horizon march serves all three: `T + V_hf = full - (T + V_blockers) + T`.
//! Cost per shaded pixel beyond the beauty: one sphere-cap sum and three exponentiations
//! (the combined numerator is the diffuse term's own); fewer when the scene has no
//! height field or no blockers, whose ratio is then the combined one.

use super::{Caps, KnownAlongSun, Occluders, ShadingKernel, SurfacePoint};
use crate::scene::Material;
use crate::sh::{coefficient_count, Real, MAX_COEFFICIENTS};

/// Rec. 709 / sRGB luminance weights of linear R, G, B.
pub const LUMINANCE: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// One surface point's radiance by pass, and its visibility terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelPasses {
    /// `albedo * exp*(visibility + diffuse lobe) . light`.
    pub diffuse: [f32; 3],
    /// `specular * exp*(visibility + Phong lobe) . light`; black for non-Phong materials.
    pub specular: [f32; 3],
    /// Height field and blockers together, in `[0, 1]` up to SH ringing.
    pub visibility: f32,
    /// The height field alone (1 where the scene has none).
    pub visibility_heightfield: f32,
    /// The sphere blockers alone (1 where the frame has none).
    pub visibility_blockers: f32,
}

impl PixelPasses {
    /// Black, unoccluded: a pixel with nothing to shade.
    pub const UNSHADED: PixelPasses = PixelPasses {
        diffuse: [0.0; 3],
        specular: [0.0; 3],
        visibility: 1.0,
        visibility_heightfield: 1.0,
        visibility_blockers: 1.0,
    };
}

/// `lum(numerator) / lum(unoccluded)`, or 1 where the unoccluded receiver gets no light
/// (a black light shadows nothing).
pub(crate) fn ratio<T: Real>(numerator: [T; 3], unoccluded: [T; 3]) -> f32 {
    let lum = |c: [T; 3]| (0..3).map(|i| LUMINANCE[i] * c[i].to_f64().unwrap_or(0.0)).sum::<f64>();
    let below = lum(unoccluded);
    if below > 1e-12 {
        (lum(numerator) / below) as f32
    } else {
        1.0
    }
}

impl<T: Real> ShadingKernel<T> {
    /// [`shade`](Self::shade), split into passes, with the visibility terms (module doc).
    pub fn shade_passes(&self, occluders: Occluders, point: &SurfacePoint, caps: Caps) -> PixelPasses {
        self.shade_passes_known(occluders, point, caps, None)
    }

    /// [`Self::shade_passes`], each sun's horizon taken from `known` where given
    /// ([`Self::shade_lobes_known`]).
    pub fn shade_passes_known(
        &self,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        known: Option<&[KnownAlongSun]>,
    ) -> PixelPasses {
        let count = coefficient_count(self.order);
        let (p, n) = (point.position, point.normal);
        let Some((full, occlusion)) = self.surface_visibility(occluders, point, caps, None) else {
            return PixelPasses::UNSHADED;
        };
        let lobes = &self.materials[&point.material];
        if matches!(lobes.material, Material::Water { .. }) {
            return PixelPasses::UNSHADED;
        }
        let (lit_diffuse, diffuse, specular) = self.environment_lit(occluders, &full, &occlusion, lobes, point);
        let (sun_diffuse, sun_glossy) = self.sharp_lit(occluders, point, &lobes.material, &self.suns, true, known).0;
        let diffuse = [0, 1, 2].map(|i| diffuse[i] + sun_diffuse[i]);
        let specular = [0, 1, 2].map(|i| specular[i] + sun_glossy[i]);

        let none = Occluders { blockers: None, horizons: None, sun_shadows: None };
        let mut unoccluded = [T::zero(); MAX_COEFFICIENTS];
        self.add_visibility(none, p, n, point.object, &mut unoccluded[..count]);
        let lit_unoccluded = self.lit(&unoccluded, &self.diffuse, n);
        let visibility = ratio(lit_diffuse, lit_unoccluded);
        let (visibility_heightfield, visibility_blockers) =
            self.split_visibility(occluders, point, caps, &full, &unoccluded, visibility, |_, log| {
                ratio(self.lit(log, &self.diffuse, n), lit_unoccluded)
            });
        PixelPasses { diffuse, specular, visibility, visibility_heightfield, visibility_blockers }
    }
}
