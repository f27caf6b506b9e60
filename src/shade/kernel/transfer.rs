//! The kernel's shading kept as transfer vectors (`logsh render --transfer`,
//! [`crate::transfer`]): what [`ShadingKernel::shade_passes`] dots with the light, before
//! the dot, so that any other light relights the point.
//!
//! `exp*(V + lobe)` does not depend on the light (paper 000, Eq. 9: visibility and BRDF are
//! summed in log space, the light enters only in the final dot product), so
//! `max(exp*(V + D) . L', 0)` is the diffuse term under any light `L'` with exactly the
//! visibility the point had, corrected at the point's normal to the map's irradiance as
//! [`ShadingKernel::open_corrected`] corrects it (the normal is kept, and the open
//! receiver's ZH in the header). The prefiltered glossy term keeps what does not depend on
//! the light (the cone test, the lobe's albedo, the mirror direction) and the transfer its
//! log-SH share of the specular occlusion needs; the scene's own lamps are light that a
//! relight leaves where it was, kept as radiance.

use super::{
    as_f32_array, occlusion_ratio, open_lit, visibility_ratio, Caps, KnownAlongSun, OccluderSet, Occluders,
    PixelPasses, ShadingKernel, SurfacePoint,
};
use crate::heightfield::HORIZON_SECTORS;
use crate::scene::Material;
use crate::sh::{coefficient_count, Real, MAX_COEFFICIENTS};
use crate::shade::glossy::SharpLobe;
use crate::shade::sun::SunDisk;

/// How a point's glossy term reads the light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GlossyTransfer {
    /// No glossy term.
    None,
    /// `--glossy sh` (or a light without a map): `max(specular_transfer . L, 0)`.
    Sh,
    /// The prefiltered map of the material's lobe along `direction`, times
    /// `cone + sh_weight * ratio`, `ratio` the log-SH share of the specular occlusion
    /// under the light (`ShadingKernel::prefiltered_glossy`).
    Prefiltered { material: u32, direction: [f64; 3], cone: f64, sh_weight: f64 },
}

/// One surface point's transfer vectors (`coefficient_count(order)` entries each) and
/// the light-independent rest of its shading, before any water tint.
#[derive(Clone, Copy, Debug)]
pub struct PointTransfer {
    /// `exp*(V + D)`: the diffuse term is `albedo * max(diffuse . L, 0)`.
    pub diffuse: [f32; MAX_COEFFICIENTS],
    /// `exp*(T + D)`, the receiver without blockers or height field: the denominator of
    /// the visibility passes.
    pub unoccluded: [f32; MAX_COEFFICIENTS],
    /// The numerators of `visibility_heightfield` and `visibility_blockers` where the
    /// frame has both (otherwise each equals `diffuse` or `unoccluded`).
    pub heightfield: [f32; MAX_COEFFICIENTS],
    pub blockers: [f32; MAX_COEFFICIENTS],
    /// `exp*(V + Phong lobe about R)` with `--glossy sh`, `exp*(V_occlusion + Phong lobe)`
    /// for the prefiltered term; zero without a glossy term.
    pub specular: [f32; MAX_COEFFICIENTS],
    pub glossy: GlossyTransfer,
    pub albedo: [f32; 3],
    pub specular_colour: [f32; 3],
    /// The scene's Sun and point lamps' share of the diffuse and specular passes (albedo
    /// and specular colour applied): light that a relight of the environment keeps, but
    /// for the Sun lamps' part when it turns them.
    pub lamps_diffuse: [f32; 3],
    pub lamps_specular: [f32; 3],
    /// The Sun lamps' part of `lamps_*` (what a relight that turns them takes out).
    pub sun_lamps_diffuse: [f32; 3],
    pub sun_lamps_specular: [f32; 3],
    /// The height field's highest horizon tangent in each sector of the W azimuths,
    /// rounded up, where they were marched (infinite otherwise): what bounds the horizons
    /// of the Sun lamps a relight turns ([`crate::heightfield::HorizonsBetween`]).
    pub horizons: [f32; HORIZON_SECTORS],
    /// The normal at which the diffuse light was corrected to the map's irradiance
    /// ([`ShadingKernel::open_corrected`]): the point's own.
    pub normal: [f32; 3],
}

impl PointTransfer {
    /// A point that nothing lights.
    pub const DARK: PointTransfer = PointTransfer {
        diffuse: [0.0; MAX_COEFFICIENTS],
        unoccluded: [0.0; MAX_COEFFICIENTS],
        heightfield: [0.0; MAX_COEFFICIENTS],
        blockers: [0.0; MAX_COEFFICIENTS],
        specular: [0.0; MAX_COEFFICIENTS],
        glossy: GlossyTransfer::None,
        albedo: [0.0; 3],
        specular_colour: [0.0; 3],
        lamps_diffuse: [0.0; 3],
        lamps_specular: [0.0; 3],
        sun_lamps_diffuse: [0.0; 3],
        sun_lamps_specular: [0.0; 3],
        horizons: [f32::INFINITY; HORIZON_SECTORS],
        normal: [0.0; 3],
    };
}

impl<T: Real> ShadingKernel<T> {
    /// The prefiltered glossy lobes, by material: the lobe and its exponentiated ZH about
    /// +Z (`super::SharpGlossy::open`).
    pub fn prefiltered_lobes(&self) -> Vec<(u32, SharpLobe, Vec<f64>)> {
        let lobes = self.materials.iter().filter_map(|(&index, lobes)| lobes.sharp.as_ref().map(|s| (index, s)));
        lobes
            .map(|(index, sharp)| (index, sharp.lobe, sharp.open.iter().map(|v| v.to_f64().unwrap_or(0.0)).collect()))
            .collect()
    }

    /// Whether the prefiltered glossy term's map has its lower hemisphere black: a ground
    /// plane or a height field hides it.
    pub fn sky_only(&self) -> bool {
        self.sky_only
    }

    /// The open receiver's diffuse ZH about +Z, `exp*(T + D)`, where the diffuse light is
    /// corrected to the map's irradiance ([`Self::open_corrected`]); `None` where it is not
    /// (a light without a map).
    pub fn open_diffuse(&self) -> Option<Vec<f64>> {
        self.irradiance.as_ref()?;
        Some(self.diffuse_open.iter().map(|v| v.to_f64().unwrap_or(0.0)).collect())
    }

    /// `exp*(visibility + lobe about axis)`, floored as [`Self::lit`] floors it, into `out`:
    /// in f32 lanes where `lit` folds the light ([`crate::sh::FoldedQuadrature::project`]).
    fn transfer(&self, visibility: &[T], lobe: &super::LobeTable<T>, axis: [f64; 3], out: &mut [f32]) {
        let count = coefficient_count(self.order);
        let f = self.with_lobe(visibility, lobe, axis);
        if let Some(folded) = &self.folded {
            let (f32s, v32s) = (as_f32_array(&f[..count]), as_f32_array(&visibility[..count]));
            let floored = self.overlap_floor.then(|| (&v32s[..count], self.log_epsilon.to_f32().unwrap_or(0.0)));
            return folded.project(&f32s[..count], floored, lobe.log_peak as f32, out);
        }
        let floored = self.overlap_floor.then(|| (&visibility[..count], self.log_epsilon.to_f64().unwrap_or(0.0)));
        let mut e = [T::zero(); MAX_COEFFICIENTS];
        self.exp.exp(&f[..count], floored, lobe.log_peak, &mut e[..count]);
        for (o, v) in out[..count].iter_mut().zip(&e[..count]) {
            *o = v.to_f32().unwrap_or(0.0);
        }
    }

    /// The light of `suns` at `point`, diffuse and specular, as
    /// [`shade_transfer`](Self::shade_transfer) shades the scene's Sun lamps into
    /// `lamps_*` (here without the point lamps); `None` where `shade_transfer` is dark (a
    /// material the kernel does not know). `suns` need not be the kernel's: a relight
    /// turns the lamps it was built with. `known`, where given, holds what the frame's
    /// pass found of each sun's occluders at `point` with the pixels beside it (its
    /// horizon, whether a blocker can reach it; the same bits).
    pub fn sun_lamps_lit(
        &self,
        occluders: Occluders,
        point: &SurfacePoint,
        suns: &[SunDisk],
        known: Option<&[KnownAlongSun]>,
    ) -> Option<([f32; 3], [f32; 3])> {
        let lobes = self.materials.get(&point.material)?;
        Some(self.sharp_lit(occluders, point, &lobes.material, suns, false, known).0)
    }

    /// The transfer of `point` (module doc), and its passes as
    /// [`shade_passes`](Self::shade_passes) gives them, computed from the transfer: the
    /// visibility is summed and exponentiated once for both. The passes differ from
    /// `shade_passes`' by the f32 kernel's folded quadrature against the projection and
    /// dot here (2e-5 relative, [`crate::sh::folded`]). [`PointTransfer::DARK`] and
    /// unshaded passes for an unknown material or water (whose caller transfers the
    /// reflected point instead). `scene_suns` is how many of the kernel's suns are the
    /// scene's own Sun lamps (the rest were taken out of the map, and a relight holds them
    /// in SH).
    pub fn shade_transfer(
        &self,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        scene_suns: usize,
    ) -> (PixelPasses, PointTransfer) {
        let count = coefficient_count(self.order);
        let (p, n) = (point.position, point.normal);
        let dark = (PixelPasses::UNSHADED, PointTransfer::DARK);
        let mut horizons = [f32::INFINITY; HORIZON_SECTORS];
        let Some((full, occlusion)) = self.surface_visibility(occluders, point, caps, Some(&mut horizons)) else {
            return dark;
        };
        let lobes = &self.materials[&point.material];
        let (albedo, specular_colour) = match &lobes.material {
            Material::Diffuse { albedo } | Material::Heightfield { albedo } => (*albedo, [0.0; 3]),
            Material::Phong { albedo, specular, .. } => (*albedo, *specular),
            Material::Water { .. } => return dark,
        };
        // The render's light (its suns taken out), as the passes dot it.
        let lit = |t: &[f32]| -> [f32; 3] {
            self.light
                .each_ref()
                .map(|l| l.iter().zip(&t[..count]).map(|(a, b)| a.to_f32().unwrap_or(0.0) * b).sum::<f32>().max(0.0))
        };
        let normal = n.map(|c| c as f32);
        let mut out = PointTransfer { albedo, specular_colour, horizons, normal, ..PointTransfer::DARK };
        self.transfer(&full, &self.diffuse, n, &mut out.diffuse);
        let none = Occluders { blockers: None, horizons: None, sun_shadows: None };
        let mut unoccluded = [T::zero(); MAX_COEFFICIENTS];
        self.add_visibility(none, p, n, point.object, &mut unoccluded[..count]);
        self.transfer(&unoccluded, &self.diffuse, n, &mut out.unoccluded);
        let (lit_diffuse, lit_unoccluded) = (lit(&out.diffuse), lit(&out.unoccluded));
        let visibility = visibility_ratio(lit_diffuse, lit_unoccluded);
        let diffuse_light =
            self.open_corrected(lit_diffuse.map(|c| T::of(f64::from(c))), n).map(|c| c.to_f32().unwrap_or(0.0));
        let (visibility_heightfield, visibility_blockers) =
            self.split_visibility(occluders, point, caps, &full, &unoccluded, visibility, |set, log| {
                let transfer = match set {
                    OccluderSet::Heightfield => &mut out.heightfield,
                    OccluderSet::Blockers => &mut out.blockers,
                };
                self.transfer(log, &self.diffuse, n, transfer);
                visibility_ratio(lit(transfer), lit_unoccluded)
            });
        let mut glossy = [0.0f32; 3];
        if let Material::Phong { .. } = lobes.material {
            let phong = lobes.phong.as_ref().expect("phong materials carry their lobe");
            let reflected = super::reflect_view(point.view_origin, p, n);
            out.glossy = match &lobes.sharp {
                Some(sharp) => {
                    let (cone, sh_weight) = self.prefiltered_weights(occluders, sharp, point, reflected);
                    let by_sh = if sh_weight > 0.0 {
                        self.transfer(&occlusion, phong, reflected, &mut out.specular);
                        let open = open_lit(self.order, &sharp.open, reflected, &self.light)
                            .map(|v| v.to_f32().unwrap_or(0.0));
                        occlusion_ratio(lit(&out.specular), open)
                    } else {
                        0.0
                    };
                    let weight = cone + sh_weight * by_sh;
                    glossy = sharp.prefiltered.lookup(reflected).map(|c| (f64::from(c) * weight) as f32);
                    GlossyTransfer::Prefiltered { material: point.material, direction: reflected, cone, sh_weight }
                }
                None => {
                    self.transfer(&full, phong, reflected, &mut out.specular);
                    glossy = lit(&out.specular);
                    GlossyTransfer::Sh
                }
            };
        }
        let scene_suns = scene_suns.min(self.suns.len());
        ((out.lamps_diffuse, out.lamps_specular), (out.sun_lamps_diffuse, out.sun_lamps_specular)) =
            self.sharp_lit(occluders, point, &lobes.material, &self.suns[..scene_suns], true, None);
        let (extracted_diffuse, extracted_specular) =
            self.sharp_lit(occluders, point, &lobes.material, &self.suns[scene_suns..], false, None).0;
        let passes = PixelPasses {
            diffuse: [0, 1, 2].map(|k| diffuse_light[k] * albedo[k] + (out.lamps_diffuse[k] + extracted_diffuse[k])),
            specular: [0, 1, 2]
                .map(|k| glossy[k] * specular_colour[k] + (out.lamps_specular[k] + extracted_specular[k])),
            visibility,
            visibility_heightfield,
            visibility_blockers,
        };
        (passes, out)
    }
}
