//! The per-pixel shading kernel: sum log vectors, exponentiate, dot with the light
//! (paper 000, Sections 4-5 and Eq. 9). The CPU executor of the pipeline; the tables it
//! holds are the ones a GPU executor uploads.

use super::blocker_tree::BlockerTree;
use super::cap_detail::CapDetail;
use super::cap_packet::{CapPacket, Receiver, LANES};
pub use super::exponentiator::{quadrature_weight, sh_space_max_magnitude, Exponentiator, SH_SPACE_BLEND};
use super::fitted_depth::{
    band_coverages, band_depths_for, banded_slice_of_tangents, banded_slices_of_tangents, depth_at, fitted_depths,
    horizon_coverage, overlapped_depth, DepthKey, DEPTH_INTERVALS,
};
use super::frame::{pixel_source, PixelSource, PixelWork};
use super::glossy::{
    albedo_lookup, below_tangent_divisor, cone_share, cone_weights, environment_albedo_table, ggx_alpha,
    lamp_scale_table, share_above_table, smooth_over_disk, GgxLit, MapLevels, Prefiltered, SharpLobe,
};
pub use super::point::{above_ground, reflect_view, SurfacePoint};
use super::settings::{GlossyMethod, ShadingSettings, MAX_DIRECTIONS};
use super::sun::{Casters, DiskDirections, DiskHorizon, DiskShape, Planes, SunDisk, DISK_DIRECTIONS};
use super::sun_shadow::SunShadows;
use crate::heightfield::{HorizonAgainst, HorizonPyramid};
use crate::logsh::{
    cap_log_zh, lobe_log_zh_as, shared_optimal_lobe_epsilon, view_blocker, BlockerView, Lobe, WedgeOperator, WedgeTurn,
};
use crate::scene::{EnvironmentMap, Light, Material, PointLight, SunLight};
use crate::sh::basis::{clamped_cosine_factor, funk_hecke_factor};
use crate::sh::{add_rotated_zonal, coefficient_count, ExpMethod, FoldedQuadrature, Real, MAX_COEFFICIENTS};
use crate::vector::dot;
use rayon::prelude::*;
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::f64::consts::FRAC_PI_2;
use std::sync::Arc;

/// A lobe's log-ZH table and the log of its peak (the most its log function reaches).
#[derive(Clone, Debug)]
pub(crate) struct LobeTable<T> {
    pub(crate) zonal: Vec<T>,
    pub(crate) log_peak: f64,
}

impl<T: Real> LobeTable<T> {
    fn new(order: usize, lobe: Lobe, epsilon: f64) -> Self {
        Self { zonal: lobe_log_zh_as(order, lobe, epsilon), log_peak: lobe.peak().ln() }
    }
}

/// The BRDF lobes of one material.
#[derive(Clone, Debug)]
pub(crate) struct MaterialLobes<T> {
    pub(crate) material: Material,
    /// Phong lobe (Eq. 27) for `phong` materials: the glossy term itself with
    /// `--glossy sh`, else the lobe of the specular occlusion.
    pub(crate) phong: Option<LobeTable<T>>,
    /// The prefiltered glossy term ([`super::glossy`]) of `phong` materials, unless
    /// `--glossy sh` or the light has no map.
    pub(crate) sharp: Option<SharpGlossy<T>>,
}

/// The tables of one material's prefiltered glossy term ([`super::glossy`]).
#[derive(Clone, Debug)]
pub(crate) struct SharpGlossy<T> {
    pub(crate) lobe: SharpLobe,
    /// The light prefiltered with `lobe` (shared by materials of the same lobe).
    pub(crate) prefiltered: Arc<Prefiltered>,
    /// The lobe's albedo over `n . v` ([`super::glossy::albedo_table`]).
    pub(crate) albedo: Vec<f32>,
    /// The lobe's share above the tangent plane over `n . R`
    /// ([`super::glossy::share_above_table`]).
    pub(crate) share_above: Vec<f32>,
    /// What a sharp light's glossy term is scaled by over `n . v`
    /// ([`super::glossy::lamp_scale_table`]).
    pub(crate) lamp_scale: Vec<f32>,
    /// The reflectance at normal incidence of the Fresnel term sharp lights reflect with
    /// ([`super::glossy::ggx_lit`]): 1 (none) on converted materials.
    pub(crate) lamp_fresnel: f64,
    /// `exp*(Phong lobe)` about +Z as ZH: the unoccluded denominator of the specular
    /// occlusion.
    pub(crate) open: Vec<T>,
    /// The share of the specular occlusion the cone test gives ([`super::glossy::cone_share`]).
    pub(crate) cone_share: f64,
    /// The cone's directions' weights ([`super::glossy::cone_weights`]).
    pub(crate) cone_weights: [f64; DISK_DIRECTIONS],
    /// The cone's directions about +Z.
    pub(crate) core: DiskShape,
}

/// Bands of [`OpenIrradiance`]: the clamped cosine's ZH falls as `l^-5/2`, so the bands
/// from 8 on hold under 0.5 % of an open receiver's light under any map.
pub const IRRADIANCE_ORDER: usize = crate::sh::MAX_ORDER;

/// `E(n) / pi` of the light's map, the open receiver's diffuse light in full: the map's
/// order-8 projection dotted with the clamped cosine rotated to `n` (Ramamoorthi and
/// Hanrahan 2001, with four more bands), evaluated per receiver.
#[derive(Clone, Debug)]
pub(crate) struct OpenIrradiance {
    /// The map's SH coefficients per colour channel, `IRRADIANCE_ORDER^2` each.
    light: [Vec<f64>; 3],
    /// ZH of `max(cos, 0) / pi` about +Z, `IRRADIANCE_ORDER` values.
    cosine: Vec<f64>,
}

impl OpenIrradiance {
    /// The irradiance of `map` times `strength`.
    pub(crate) fn new(map: &EnvironmentMap, strength: f32) -> Self {
        let order = IRRADIANCE_ORDER;
        let coefficients = crate::scene::light::project_texels(map, order);
        let channel = |c: usize| coefficients.iter().map(|rgb| rgb[c] * f64::from(strength)).collect::<Vec<f64>>();
        // A ZH turned to `n` is scaled by the Funk-Hecke factor (paper 000, Eq. 5).
        let cosine =
            (0..order).map(|l| clamped_cosine_factor(l) / (std::f64::consts::PI * funk_hecke_factor(l))).collect();
        Self { light: [channel(0), channel(1), channel(2)], cosine }
    }

    /// The coefficients the GPU pass dots with the basis at `n` (`irradiance_at` in
    /// `shaders/shade.wgsl`): per channel, each light coefficient times its band's
    /// rotated cosine, `IRRADIANCE_ORDER^2` values each.
    pub(crate) fn weighted_light(&self) -> [Vec<f64>; 3] {
        self.light.each_ref().map(|light| {
            light
                .iter()
                .enumerate()
                .map(|(i, l)| {
                    let band = (i as f64).sqrt() as usize;
                    l * funk_hecke_factor(band) * self.cosine[band]
                })
                .collect()
        })
    }

    /// `E(n) / pi` per colour channel.
    pub(crate) fn at(&self, n: [f64; 3]) -> [f64; 3] {
        let count = IRRADIANCE_ORDER * IRRADIANCE_ORDER;
        let mut rotated = [0.0f64; MAX_COEFFICIENTS];
        add_rotated_zonal(IRRADIANCE_ORDER, &self.cosine, 1.0, n, &mut rotated[..count]);
        self.light.each_ref().map(|light| light.iter().zip(&rotated[..count]).map(|(l, r)| l * r).sum())
    }
}

/// The open receiver's log-SH light below which [`ShadingKernel::open_corrected`] keeps
/// log-SH's own value: a channel the light leaves dark.
pub(crate) const OPEN_LIGHT_FLOOR: f64 = 1e-6;

/// The sharpest Phong lobe given to log-SH (the glossy term with `--glossy sh`, the
/// specular occlusion's lobe otherwise): the log-ZH tables are exact up to it
/// ([`crate::logsh::lobe_log_zh`]), and no order up to 8 tells a sharper lobe from it.
pub const SH_MAX_EXPONENT: f64 = 1024.0;

/// The map the glossy term reflects: the light's own map (its suns taken out, which the
/// sun term reflects), a constant light as a small constant map; `None` for a light
/// given only as SH coefficients.
pub(crate) fn glossy_map(light: &Light) -> Option<(Cow<'_, EnvironmentMap>, f32)> {
    match light {
        Light::Environment { map, strength } => Some((Cow::Borrowed(map), *strength)),
        Light::Constant(c) => Some((
            Cow::Owned(EnvironmentMap { file: "constant light".into(), width: 16, height: 8, texels: vec![*c; 128] }),
            1.0,
        )),
        Light::Sh(_) => None,
    }
}

/// What a pass over a frame's pixels knows of a sun's occluders at one pixel before
/// shading it, found with the pixels beside it ([`ShadingKernel::sun_lamps_lit`]).
#[derive(Clone, Copy, Debug)]
pub struct KnownAlongSun {
    /// The height field's horizon along the sun, marched with the other pixels
    /// ([`HorizonPyramid::horizons_against`], the same bits); `None` to march it here.
    pub horizon: Option<HorizonAgainst>,
    /// Whether a blocker may reach the sun's disk from the pixel
    /// ([`DiskDirections::blockers_may_reach`]): where none can, the pixel does not walk
    /// the blockers, whose walk would see none.
    pub blockers: bool,
}

/// What occludes a frame: its sphere blockers, its height-field pyramid and its suns'
/// shadow maps.
#[derive(Clone, Copy)]
pub struct Occluders<'a> {
    /// `None` without blockers.
    pub blockers: Option<&'a BlockerTree>,
    pub horizons: Option<&'a HorizonPyramid>,
    /// The suns' shadow maps of the blocker meshes, `None` without any.
    pub sun_shadows: Option<&'a SunShadows>,
}

impl<'a> Occluders<'a> {
    /// A frame's occluders as its plan holds them: an empty tree or set of maps is none.
    pub fn of(blockers: &'a BlockerTree, horizons: Option<&'a HorizonPyramid>, sun_shadows: &'a SunShadows) -> Self {
        Self {
            blockers: (!blockers.is_empty()).then_some(blockers),
            horizons,
            sun_shadows: (!sun_shadows.is_empty()).then_some(sun_shadows),
        }
    }
}

/// Where a point's sphere caps (and height-field horizons) come from: walked and marched
/// for it alone, the caps summed ahead with the other receivers of its packet
/// ([`ShadingKernel::sum_caps`]), or both interpolated from a coarser grid of receivers
/// ([`super::visibility_grid`]).
#[derive(Clone, Copy, Debug)]
pub enum Caps<'a> {
    Walk,
    /// The caps' log vector, `order^2` coefficients.
    Summed(&'a [f32]),
    /// Interpolated: the caps' log vector (`None` without blockers) and the tangents of
    /// the horizons along the kernel's azimuths (`None` without a height field).
    Grid {
        caps: Option<&'a [f64]>,
        horizons: Option<&'a [f64]>,
        /// The height field's log vector, the tangent plane folded in
        /// ([`ShadingKernel::heightfield_log`]), and how much the pixel takes it rather
        /// than turn its own horizons (0 to 1).
        heightfield: Option<(&'a [f64], f64)>,
    },
}

/// The sphere caps of a run of points, summed in packets where the kernel runs in f32 on
/// a processor with AVX2 ([`CapPacket`]); otherwise each point walks the tree itself.
#[derive(Clone, Debug, Default)]
pub struct CapSums {
    count: usize,
    sums: Vec<f32>,
}

impl CapSums {
    /// The caps of the `k`-th point.
    pub fn of(&self, k: usize) -> Caps<'_> {
        match self.sums.get(k * self.count..(k + 1) * self.count) {
            Some(sum) if self.count > 0 => Caps::Summed(sum),
            _ => Caps::Walk,
        }
    }
}

/// Tables and settings for one frame's shading at precision `T`.
pub struct ShadingKernel<T> {
    pub(crate) order: usize,
    pub(crate) log_epsilon: T,
    /// Each cap's log depth per angular radius and each horizon band's per width
    /// ([`super::fitted_depth`]): fitted, or `log(eps)` throughout.
    pub(crate) cap_depths: Vec<T>,
    /// `cap_depths` in f32, as the packets read them ([`CapPacket`]).
    cap_depths_f32: Vec<f32>,
    /// Each horizon band's log depth per width, a row of widths per horizon coverage.
    pub(crate) band_depths: Vec<T>,
    /// The horizon coverage of each row of `band_depths` ([`band_coverages`]).
    pub(crate) band_coverages: Vec<f64>,
    pub(crate) ratio_attenuation: bool,
    pub(crate) tangent_occlusion: bool,
    /// Floor the log visibility at `log(eps)` per quadrature node
    /// ([`ShadingSettings::overlap_floor`]).
    pub(crate) overlap_floor: bool,
    pub(crate) exp: Exponentiator,
    pub(crate) wedge: Option<WedgeOperator>,
    /// The wedge operator's full turn in `T`.
    wedge_turn: Option<WedgeTurn<T>>,
    /// Each wedge azimuth's `(sin, cos)`.
    azimuths: Vec<(f64, f64)>,
    pub(crate) diffuse: LobeTable<T>,
    /// Log-ZH of the hemisphere behind the tangent plane, around -Z before rotation.
    pub(crate) tangent: Vec<T>,
    /// The same hemisphere about -Z as SH: the ground plane's log visibility.
    below_horizon: Vec<T>,
    /// The height field's slices with every horizon at the horizontal, turned by the wedge
    /// operator: the `log(eps)` each slice holds below the horizontal, which the specular
    /// occlusion takes back out ([`Self::add_visibility_parts`]). Empty without a height
    /// field.
    pub(crate) below_horizontal_slices: Vec<T>,
    pub(crate) materials: BTreeMap<u32, MaterialLobes<T>>,
    /// Light SH coefficients per colour channel.
    pub(crate) light: [Vec<T>; 3],
    /// The light folded into the quadrature, for [`Self::lit`] in f32 with `quad` or
    /// `exact` ([`FoldedQuadrature`]).
    pub(crate) folded: Option<FoldedQuadrature>,
    /// The sharp lights, shaded outside SH ([`super::sun`]).
    pub(crate) suns: Vec<SunDisk>,
    /// The point lamps, each a disk built per receiver ([`SunDisk::of_lamp`]).
    pub(crate) points: Vec<PointLight>,
    /// Height of the scene's ground plane, which hides the lower hemisphere from
    /// receivers above it.
    pub(crate) ground: Option<f64>,
    /// The glossy term's map has its lower hemisphere black: a ground plane or a height
    /// field hides it ([`super::glossy::MapLevels::new`]).
    pub(crate) sky_only: bool,
    /// `E(n) / pi` of the light's map: the open receiver's diffuse light in full, which
    /// log-SH's `exp*(T + D) . L` at order n approximates (none for a light given as SH
    /// alone).
    pub(crate) irradiance: Option<OpenIrradiance>,
    /// `exp*(T + D)` about +Z as ZH: the open receiver's diffuse transfer in log-SH.
    pub(crate) diffuse_open: Vec<T>,
    /// The light's detail beyond order n over sphere caps, which [`Self::hidden_detail`]
    /// takes from the diffuse light (none without blockers, a map, or `cap_detail`).
    pub(crate) cap_detail: Option<CapDetail>,
}

impl<T: Real> ShadingKernel<T> {
    /// Builds the tables. `light` holds `order^2` RGB coefficients of `residual` (the
    /// scene's light with its suns taken out), whose map the glossy term reflects;
    /// `has_heightfield` decides whether the wedge operator is built at all, `has_blockers`
    /// whether the caps' detail table is ([`CapDetail`]); `suns` and
    /// `points` are the sharp lights; `ground` the height of the scene's ground plane;
    /// `lamp_fresnel`: each Phong material's reflectance at normal incidence for the sharp
    /// lights' Fresnel term ([`super::glossy::lamp_fresnel`]);
    /// `colour_passes`: the G-buffer's Glossy Color weighs each glossy lobe
    /// ([`crate::scene::gbuffer`], "Colour passes"). That pass is Cycles' estimate of the
    /// specular layer's albedo under a white sky, Fresnel and the lobe's own energy
    /// included (Principled's multiple-scattering GGX keeps it), so the prefiltered lobe's
    /// albedo `A(n . v)` ([`super::glossy`]) is 1 there: with it, the textured measurement
    /// scene came out 0.0089 from Cycles as authored, without it 0.0071 (the gold torus
    /// 0.018 and 0.014, in units of the open floor).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        settings: &ShadingSettings,
        materials: &BTreeMap<u32, Material>,
        lamp_fresnel: &BTreeMap<u32, f64>,
        colour_passes: bool,
        light: &[[f64; 3]],
        residual: &Light,
        has_heightfield: bool,
        has_blockers: bool,
        suns: &[SunLight],
        points: &[PointLight],
        ground: Option<f64>,
    ) -> Self {
        let order = settings.order;
        let epsilon = settings.epsilon;
        let mut tangent = vec![T::zero(); order];
        cap_log_zh(order, T::of(epsilon.ln()), T::of(FRAC_PI_2), &mut tangent);
        let exp = Exponentiator::new(order, settings.exp, settings.hyb_threshold);
        let sky_only = ground.is_some() || has_heightfield;
        let materials =
            Self::material_lobes(settings, materials, lamp_fresnel, colour_passes, residual, sky_only, &exp);
        let (cap_depths, band_depths, band_coverages) = Self::depth_tables(settings, has_heightfield, &exp);
        let wedge = has_heightfield.then(|| WedgeOperator::new(order, settings.horizon.directions));
        let channel = |c: usize| light.iter().map(|rgb| T::of(rgb[c])).collect::<Vec<T>>();
        // The f32 path dots with the light inside the quadrature (`crate::sh::folded`).
        let folded = (is_f32::<T>() && matches!(exp.method, ExpMethod::Quad | ExpMethod::Exact)).then(|| {
            let channel64 = |c: usize| light.iter().map(|rgb| rgb[c]).collect::<Vec<f64>>();
            FoldedQuadrature::new(
                exp.exact.as_ref().expect("always built"),
                &[channel64(0), channel64(1), channel64(2)],
            )
        });
        let diffuse_open: Vec<T> = {
            let table: LobeTable<T> = LobeTable::new(order, Lobe::Diffuse, epsilon);
            let count = coefficient_count(order);
            let mut f = vec![T::zero(); count];
            add_rotated_zonal(order, &table.zonal, T::one(), [T::zero(), T::zero(), T::one()], &mut f);
            if settings.tangent_occlusion {
                add_rotated_zonal(order, &tangent, T::one(), [T::zero(), T::zero(), -T::one()], &mut f);
            }
            let mut e = vec![T::zero(); count];
            exp.exp(&f, None, table.log_peak, &mut e);
            (0..order).map(|l| e[l * l + l]).collect()
        };
        let mut kernel = Self {
            order,
            log_epsilon: T::of(epsilon.ln()),
            cap_depths_f32: cap_depths.iter().map(|d| d.to_f32().unwrap_or(0.0)).collect(),
            cap_depths,
            band_depths,
            band_coverages,
            ratio_attenuation: settings.ratio_attenuation,
            tangent_occlusion: settings.tangent_occlusion,
            overlap_floor: settings.overlap_floor,
            exp,
            wedge_turn: wedge.as_ref().map(WedgeOperator::turn),
            azimuths: wedge.as_ref().map_or(Vec::new(), |wedge| {
                (0..wedge.directions).map(|k| (wedge.wedge_width() * k as f64).sin_cos()).collect()
            }),
            wedge,
            diffuse: LobeTable::new(order, Lobe::Diffuse, epsilon),
            below_horizon: {
                let mut below = vec![T::zero(); coefficient_count(order)];
                add_rotated_zonal(order, &tangent, T::one(), [T::zero(), T::zero(), -T::one()], &mut below);
                below
            },
            tangent,
            materials,
            light: [channel(0), channel(1), channel(2)],
            folded,
            suns: suns.iter().map(SunDisk::new).collect(),
            points: points.to_vec(),
            ground,
            sky_only,
            irradiance: glossy_map(residual).map(|(map, strength)| OpenIrradiance::new(&map, strength)),
            diffuse_open,
            cap_detail: (settings.cap_detail && has_blockers)
                .then(|| glossy_map(residual))
                .flatten()
                .map(|(map, strength)| CapDetail::new(&map, strength, order, light, sky_only)),
            below_horizontal_slices: Vec::new(),
        };
        if let (Some(wedge), Some(turn)) = (&kernel.wedge, &kernel.wedge_turn) {
            let level = [0.0f64; MAX_DIRECTIONS];
            let mut slices = vec![T::zero(); coefficient_count(order)];
            kernel.add_horizon_slices(turn, &level[..wedge.directions], None, &mut slices);
            kernel.below_horizontal_slices = slices;
        }
        kernel
    }

    /// Each material's lobes: a Phong material's log-SH lobe and, where the light has a
    /// map and `--glossy` is not `sh`, its prefiltered glossy term (materials of the same
    /// lobe share one prefiltered map).
    fn material_lobes(
        settings: &ShadingSettings,
        materials: &BTreeMap<u32, Material>,
        lamp_fresnel: &BTreeMap<u32, f64>,
        colour_passes: bool,
        residual: &Light,
        sky_only: bool,
        exp: &Exponentiator,
    ) -> BTreeMap<u32, MaterialLobes<T>> {
        let order = settings.order;
        let any_phong = materials.values().any(|m| matches!(m, Material::Phong { .. }));
        // The prefiltered glossy term's map levels, where a Phong material needs them and
        // the light has a map; otherwise every lobe stays in log-SH.
        let levels = (any_phong && settings.glossy != GlossyMethod::Sh)
            .then(|| glossy_map(residual))
            .flatten()
            .map(|(map, strength)| MapLevels::new(&map, strength, sky_only));
        let mut prefiltered: Vec<(SharpLobe, Arc<Prefiltered>)> = Vec::new();
        materials
            .iter()
            .map(|(&index, material)| {
                let (phong, sharp) = match material {
                    Material::Phong { exponent, .. } => {
                        let exponent = f64::from(*exponent);
                        let lobe = Lobe::Phong { exponent: exponent.min(SH_MAX_EXPONENT) };
                        let eps = settings.phong_epsilon.unwrap_or_else(|| shared_optimal_lobe_epsilon(order, lobe));
                        let table = LobeTable::new(order, lobe, eps);
                        let sharp = levels.as_ref().map(|levels| {
                            let sharp_lobe = match settings.glossy {
                                GlossyMethod::Phong => SharpLobe::Phong { exponent },
                                _ => SharpLobe::Ggx { alpha: ggx_alpha(exponent) },
                            };
                            let map = match prefiltered.iter().find(|(l, _)| *l == sharp_lobe) {
                                Some((_, map)) => map.clone(),
                                None => {
                                    let map = Arc::new(levels.prefilter(sharp_lobe));
                                    prefiltered.push((sharp_lobe, map.clone()));
                                    map
                                }
                            };
                            let albedo = environment_albedo_table(sharp_lobe, colour_passes);
                            let fresnel = lamp_fresnel.get(&index).copied().unwrap_or(1.0);
                            SharpGlossy {
                                lobe: sharp_lobe,
                                prefiltered: map,
                                lamp_scale: lamp_scale_table(sharp_lobe, &albedo, fresnel),
                                lamp_fresnel: fresnel,
                                albedo,
                                share_above: share_above_table(sharp_lobe),
                                open: open_lobe(order, exp, &table),
                                cone_share: cone_share(sharp_lobe, order),
                                cone_weights: cone_weights(sharp_lobe),
                                core: DiskShape::new(sharp_lobe.core_radius()),
                            }
                        });
                        (Some(table), sharp)
                    }
                    _ => (None, None),
                };
                (index, MaterialLobes { material: material.clone(), phong, sharp })
            })
            .collect()
    }

    /// The log depths of caps per radius and of horizon bands per width, and the horizon
    /// coverage of each row of the bands' table: fitted where `--fitted-depths` asks
    /// ([`super::fitted_depth`]), else `log(eps)` throughout in one row.
    fn depth_tables(
        settings: &ShadingSettings,
        has_heightfield: bool,
        exp: &Exponentiator,
    ) -> (Vec<T>, Vec<T>, Vec<f64>) {
        let (order, epsilon) = (settings.order, settings.epsilon);
        let flat = || vec![T::of(epsilon.ln()); DEPTH_INTERVALS + 1];
        if !settings.fitted_depths {
            return (flat(), flat(), vec![1.0]);
        }
        let directions = if has_heightfield { settings.horizon.directions } else { 0 };
        let key = DepthKey {
            order,
            epsilon_bits: epsilon.to_bits(),
            tangent_occlusion: settings.tangent_occlusion,
            exp: settings.exp,
            hyb_threshold_bits: settings.hyb_threshold.to_bits(),
            directions,
        };
        let fitted = fitted_depths(key, exp);
        let of = |table: &[f64]| table.iter().map(|&d| T::of(d)).collect();
        let coverages = if has_heightfield { band_coverages(directions) } else { vec![1.0] };
        (of(&fitted.caps), of(&fitted.bands), coverages)
    }

    pub fn order(&self) -> usize {
        self.order
    }

    /// The Rec. 709 luminance of the light's SH coefficients.
    pub(crate) fn light_luminance(&self) -> Vec<f64> {
        let [r, g, b] = &self.light;
        let value = |v: T| v.to_f64().unwrap_or(0.0);
        let weights = LUMINANCE;
        (0..r.len()).map(|k| weights[0] * value(r[k]) + weights[1] * value(g[k]) + weights[2] * value(b[k])).collect()
    }

    /// Computes the prefiltered texels the glossy pixels of `frame` read, in one parallel
    /// walk of its pixels ([`Prefiltered::prepare`]), for an executor that uploads them
    /// (the GPU program); the CPU path computes each texel the first time it reads it.
    pub fn prepare_glossy(&self, materials: &BTreeMap<u32, Material>, frame: &crate::scene::Frame) {
        if !self.has_prefiltered_glossy() {
            return;
        }
        let g = &frame.gbuffer;
        (0..g.width * g.height).into_par_iter().for_each(|i| {
            let PixelSource::Surface { point, .. } = pixel_source(materials, frame, i % g.width, i / g.width) else {
                return;
            };
            let Some(sharp) = self.materials.get(&point.material).and_then(|lobes| lobes.sharp.as_ref()) else {
                return;
            };
            sharp.prefiltered.prepare(reflect_view(point.view_origin, point.position, point.normal));
        });
    }

    /// Whether a material's glossy term reads a prefiltered environment.
    pub fn has_prefiltered_glossy(&self) -> bool {
        self.materials.values().any(|lobes| lobes.sharp.is_some())
    }

    /// Log visibility at `p` with unit normal `n` (Eq. 9 before exponentiation): the
    /// height field's wedges, every sphere cap in front of the tangent plane, and the
    /// hemisphere behind the tangent plane. `object` is the receiver's object index: its
    /// own spheres that hold it are skipped ([`crate::logsh::own_sphere_holds`]); distant
    /// clusters of spheres are one cap each ([`BlockerTree::visit`]).
    ///
    /// The tangent plane is clamped once. Without a height field (or for a receiver facing
    /// down, `n_z <= 0`) it is a hemisphere cap around `-n`. With one, every slice already
    /// clamps everything below its horizon, which is never under the horizontal; so the
    /// tangent plane is folded into the slices instead, raising each horizon to the plane's
    /// own elevation along that azimuth, `atan(-(n . u_k) / n_z)`. Adding the cap on top
    /// would clamp the overlap twice (`eps^2`), which paper 000 Section 4.2 warns about and
    /// which measurably brightens unoccluded terrain (1.06 instead of 1.03 at order 4).
    pub fn add_visibility(&self, occluders: Occluders, p: [f64; 3], n: [f64; 3], object: u32, acc: &mut [T]) {
        self.add_visibility_parts(occluders, p, n, object, Caps::Walk, acc, None, None);
    }

    /// [`Self::sum_caps`] of the points to shade among `work` (a row's pixels), in their
    /// order: the `k`-th [`PixelWork::Shade`] takes [`CapSums::of`]`(k)`.
    pub fn sum_caps_of_work(&self, blockers: Option<&BlockerTree>, work: &[PixelWork]) -> CapSums {
        self.sum_caps(blockers, &PixelWork::points(work))
    }

    /// The sphere caps of each of `points` ([`Self::add_visibility`]'s blocker term), summed
    /// [`LANES`] points at a time with one walk of the tree per packet ([`CapPacket`]);
    /// empty (every point walks for itself) for the f64 kernel, without blockers, or where
    /// the processor cannot run the packets.
    pub fn sum_caps(&self, blockers: Option<&BlockerTree>, points: &[SurfacePoint]) -> CapSums {
        let Some(tree) = blockers.filter(|_| is_f32::<T>() && CapPacket::available()) else {
            return CapSums::default();
        };
        let count = coefficient_count(self.order);
        let log_epsilon = self.log_epsilon.to_f32().unwrap_or(0.0);
        let packet = CapPacket::new(tree, self.order, &self.cap_depths_f32, log_epsilon, self.ratio_attenuation);
        let mut sums = vec![0.0f32; points.len() * count];
        for (chunk, out) in points.chunks(LANES).zip(sums.chunks_mut(LANES * count)) {
            let receivers: Vec<Receiver> = chunk
                .iter()
                .map(|point| Receiver {
                    position: point.position.map(|c| c as f32),
                    normal: point.normal.map(|c| c as f32),
                    object: point.object,
                })
                .collect();
            let mut lanes = [[0.0f32; MAX_COEFFICIENTS]; LANES];
            if !packet.sum(&receivers, &mut lanes) {
                return CapSums::default();
            }
            for (o, lane) in out.chunks_mut(count).zip(&lanes) {
                o.copy_from_slice(&lane[..count]);
            }
        }
        CapSums { count, sums }
    }

    /// [`add_visibility`](Self::add_visibility), and into `occlusion` when given, the part
    /// the specular occlusion reads ([`super::glossy`]): the height field above the
    /// horizontal (unfolded, less [`Self::below_horizontal_slices`]) and the blockers,
    /// without the tangent plane and the ground plane. Where the height
    /// field's horizons are marched and `horizons_found` is given, the highest tangent of
    /// each sector of their azimuths goes into it, rounded up to f32
    /// ([`HorizonPyramid::sector_maxima`](crate::heightfield::HorizonPyramid::sector_maxima):
    /// what a relight's turned Sun lamps are bounded by); it is left as it is otherwise.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn add_visibility_parts(
        &self,
        occluders: Occluders,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
        caps: Caps,
        acc: &mut [T],
        mut occlusion: Option<&mut [T]>,
        horizons_found: Option<&mut [f32]>,
    ) {
        let order = self.order;
        let nt = n.map(T::of);
        let marched = match (occluders.horizons, &self.wedge, &self.wedge_turn) {
            (Some(pyramid), Some(wedge), Some(turn)) => Some((pyramid, wedge, turn)),
            _ => None,
        };
        let fold_tangent = self.tangent_occlusion && marched.is_some() && n[2] > 0.0;
        if self.tangent_occlusion && !fold_tangent {
            add_rotated_zonal(order, &self.tangent, T::one(), nt.map(|c| -c), acc);
        }
        // The ground plane: the hemisphere below the horizontal, the tangent term's table
        // about -Z (where both overlap, the overlap floor clamps them once).
        if self.ground.is_some_and(|z| above_ground(p, z)) {
            for (a, b) in acc.iter_mut().zip(&self.below_horizon) {
                *a = *a + *b;
            }
        }
        if let Some((pyramid, wedge, turn)) = marched {
            let directions = wedge.directions;
            // The grid's interpolated log vector (not for a relight's transfer, which
            // records the horizons): whole, or blended with the pixel's own slices.
            let given = match (&caps, &horizons_found) {
                (Caps::Grid { heightfield: Some(given), .. }, None) => Some(*given),
                _ => None,
            };
            let whole = given.filter(|&(_, weight)| weight >= 1.0);
            if let Some((field, _)) = whole {
                for (a, &c) in acc.iter_mut().zip(field) {
                    *a = *a + T::of(c);
                }
            }
            if whole.is_none() || occlusion.is_some() {
                // The horizons and the tangent plane by the tangents of their elevations
                // (`banded_slice_of_tangents`).
                let mut horizons = [0.0f64; MAX_DIRECTIONS];
                match caps {
                    Caps::Grid { horizons: Some(given), .. } => horizons[..directions].copy_from_slice(given),
                    _ => pyramid.horizon_tangents(p, &mut horizons[..directions]),
                }
                if let Some(found) = horizons_found {
                    pyramid.sector_maxima(&horizons[..directions], found);
                }
                if let Some(occlusion) = occlusion.as_deref_mut() {
                    // Only what rises above the horizontal: the lobe's part below it reads
                    // the map's black lower hemisphere already ([`super::glossy`]).
                    self.add_horizon_slices(turn, &horizons[..directions], None, occlusion);
                    for (a, &b) in occlusion.iter_mut().zip(&self.below_horizontal_slices) {
                        *a = *a - b;
                    }
                }
                let fold_normal = fold_tangent.then_some(n);
                match (given, whole) {
                    (_, Some(_)) => {}
                    (None, None) => self.add_horizon_slices(turn, &horizons[..directions], fold_normal, acc),
                    (Some((field, weight)), None) => {
                        let mut own = [T::zero(); MAX_COEFFICIENTS];
                        self.add_horizon_slices(turn, &horizons[..directions], fold_normal, &mut own[..acc.len()]);
                        for ((a, &o), &f) in acc.iter_mut().zip(&own).zip(field) {
                            *a = *a + T::of(weight * f + (1.0 - weight) * o.to_f64().unwrap_or(0.0));
                        }
                    }
                }
            }
        }
        let Some(tree) = occluders.blockers else {
            return;
        };
        // The caps summed ahead, or the walk.
        let mut sum = [T::zero(); MAX_COEFFICIENTS];
        let count = match caps {
            Caps::Summed(given) => {
                for (s, &c) in sum.iter_mut().zip(given) {
                    *s = T::of(f64::from(c));
                }
                given.len()
            }
            Caps::Grid { caps: Some(given), .. } => {
                for (s, &c) in sum.iter_mut().zip(given) {
                    *s = T::of(c);
                }
                given.len()
            }
            Caps::Walk | Caps::Grid { caps: None, .. } => {
                return self.add_blocker_caps(tree, p, n, object, acc, occlusion)
            }
        };
        for (a, &c) in acc.iter_mut().zip(&sum[..count]) {
            *a = *a + c;
        }
        if let Some(occlusion) = occlusion {
            for (a, &c) in occlusion.iter_mut().zip(&sum[..count]) {
                *a = *a + c;
            }
        }
    }

    /// The height field's log vector from the tangents of its horizons' elevations along
    /// the kernel's azimuths (`banded_slice_of_tangents`, turned by the wedge operator),
    /// added to `acc`: each band from the horizontal, or from the tangent plane of
    /// `fold_normal` where given, up to its horizon takes its fitted depth; below it stays
    /// at log(eps). The fit's receiver faces +Z, so its bands start at its tangent plane: a
    /// tilted receiver's start at its own, below the horizontal on its downhill side too.
    /// The depths are those fitted for the share of the azimuths the bands cover
    /// ([`horizon_coverage`]).
    fn add_horizon_slices(&self, turn: &WedgeTurn<T>, tangents: &[f64], fold_normal: Option<[f64; 3]>, acc: &mut [T]) {
        // Eight azimuths at a time: their slices, then their part of the turn.
        const RUN: usize = 8;
        let order = self.order;
        let directions = tangents.len();
        let mut bases = [0.0f64; MAX_DIRECTIONS];
        let mut sigmas = [0.0f64; MAX_DIRECTIONS];
        sigmas[..directions].copy_from_slice(tangents);
        if let Some(n) = fold_normal {
            for (k, (base, sigma)) in bases.iter_mut().zip(sigmas.iter_mut()).take(directions).enumerate() {
                let (sin, cos) = self.azimuths[k];
                let tangent_plane = -(n[0] * cos + n[1] * sin) / n[2];
                *sigma = sigma.max(tangent_plane);
                *base = tangent_plane;
            }
        }
        let mut bands = [T::zero(); DEPTH_INTERVALS + 1];
        let coverage = horizon_coverage(&bases[..directions], &sigmas[..directions]);
        band_depths_for(&self.band_depths, &self.band_coverages, coverage, &mut bands);
        let mut slices = [T::zero(); RUN * crate::sh::MAX_ORDER];
        for (run, (bases, sigmas)) in bases[..directions].chunks(RUN).zip(sigmas[..directions].chunks(RUN)).enumerate()
        {
            self.banded_slices(&bands, bases, sigmas, &mut slices);
            turn.accumulate_from(run * RUN, &slices[..bases.len() * order], acc);
        }
    }

    /// The height field's log vector at a point with normal `n` whose horizons' tangents
    /// are `tangents`, its tangent plane folded in as [`Self::add_visibility`] folds it:
    /// what the visibility grid interpolates ([`super::visibility_grid`]). Zero without a
    /// height field.
    pub(crate) fn heightfield_log(&self, tangents: &[f64], n: [f64; 3]) -> [T; MAX_COEFFICIENTS] {
        let mut acc = [T::zero(); MAX_COEFFICIENTS];
        if let Some(turn) = &self.wedge_turn {
            let count = coefficient_count(self.order);
            let fold = (self.tangent_occlusion && n[2] > 0.0).then_some(n);
            self.add_horizon_slices(turn, tangents, fold, &mut acc[..count]);
        }
        acc
    }

    /// The log vectors of the sphere caps `tree` casts on `p` with normal `n` on object
    /// `object`, added to `acc` and, where given, to `occlusion`.
    pub(crate) fn add_blocker_caps(
        &self,
        tree: &BlockerTree,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
        acc: &mut [T],
        mut occlusion: Option<&mut [T]>,
    ) {
        let order = self.order;
        let (pt, nt) = (p.map(T::of), n.map(T::of));
        let mut zonal = [T::zero(); crate::sh::MAX_ORDER];
        let shallowest = self.cap_depths[0];
        tree.visit(p, n, object, |sphere, share| {
            let view = view_blocker(pt, nt, sphere.center.map(T::of), T::of(sphere.radius), self.ratio_attenuation);
            if let BlockerView::Cap { direction, alpha, weight } = view {
                let fitted = depth_at(&self.cap_depths, alpha);
                let depth = overlapped_depth(fitted, T::of(share), self.log_epsilon, shallowest);
                cap_log_zh(order, depth, alpha, &mut zonal[..order]);
                add_rotated_zonal(order, &zonal[..order], weight, direction, acc);
                if let Some(occlusion) = occlusion.as_deref_mut() {
                    add_rotated_zonal(order, &zonal[..order], weight, direction, occlusion);
                }
            }
        });
    }

    /// The light's detail beyond order n that the sphere caps seen from `point` hide, per
    /// colour channel ([`CapDetail`]): each cap of [`Self::add_blocker_caps`] (the same
    /// walk) weighed by its object's overlap share and by how much of it the tangent plane
    /// leaves ([`CapDetail::cap_seen`]). Zero without a table or blockers.
    pub(crate) fn hidden_detail(&self, occluders: Occluders, point: &SurfacePoint) -> [f64; 3] {
        let (Some(table), Some(tree)) = (&self.cap_detail, occluders.blockers) else {
            return [0.0; 3];
        };
        let (p, n) = (point.position, point.normal);
        let mut sum = [0.0; 3];
        tree.visit(p, n, point.object, |sphere, share| {
            if let Some((direction, alpha, cut)) = CapDetail::cap_seen(p, n, sphere.center, sphere.radius) {
                let weight = share * cut;
                for (s, d) in sum.iter_mut().zip(table.at(direction, alpha, n)) {
                    *s += weight * d;
                }
            }
        });
        sum
    }

    /// The height field's slices with bands from `bases[k]` up to `sigmas[k]` (tangents of
    /// elevations), at the depths of `bands` per width, into `out[k * order..]`:
    /// [`banded_slices_of_tangents`] in f32 lanes for
    /// the f32 kernel, slice by slice for the f64 oracle.
    fn banded_slices(&self, bands: &[T], bases: &[f64], sigmas: &[f64], out: &mut [T]) {
        let order = self.order;
        let log_epsilon = self.log_epsilon;
        if let (Some(bands32), Some(out32)) = (T::as_f32_slice(bands), T::as_f32_slice_mut(out)) {
            let log_epsilon = log_epsilon.to_f32().unwrap_or(0.0);
            banded_slices_of_tangents(order, log_epsilon, bands32, bases, sigmas, out32);
            return;
        }
        for (k, (base, sigma)) in bases.iter().zip(sigmas).enumerate() {
            banded_slice_of_tangents(order, log_epsilon, bands, *base, *sigma, &mut out[k * order..(k + 1) * order]);
        }
    }

    /// `exp*(visibility + lobe) . light` per colour channel, clamped at 0 (ringing of a
    /// band-limited product can dip below it; `max` also maps a NaN to 0, which the
    /// exponentiations are built never to produce).
    fn lit(&self, visibility: &[T], lobe: &LobeTable<T>, axis: [f64; 3]) -> [T; 3] {
        let count = coefficient_count(self.order);
        let f = self.with_lobe(visibility, lobe, axis);
        if let Some(folded) = &self.folded {
            // The kernel is f32 where it has folded quadrature: its vectors are read in place.
            let (f32s, v32s) = (T::as_f32_slice(&f[..count]), T::as_f32_slice(&visibility[..count]));
            if let (Some(f32s), Some(v32s)) = (f32s, v32s) {
                let floored = self.overlap_floor.then(|| (v32s, self.log_epsilon.to_f32().unwrap_or(0.0)));
                let ceiling = lobe.log_peak as f32;
                return folded.lit(f32s, floored, ceiling).map(|c| T::of(f64::from(c)));
            }
        }
        let mut e = [T::zero(); MAX_COEFFICIENTS];
        let floored = self.overlap_floor.then(|| (&visibility[..count], self.log_epsilon.to_f64().unwrap_or(0.0)));
        self.exp.exp(&f[..count], floored, lobe.log_peak, &mut e[..count]);
        let dot =
            |light: &[T]| light.iter().zip(&e[..count]).fold(T::zero(), |acc, (&l, &v)| acc + l * v).max(T::zero());
        [dot(&self.light[0]), dot(&self.light[1]), dot(&self.light[2])]
    }

    /// `visibility + lobe about axis`: the log function [`Self::lit`] and the transfer
    /// exponentiate.
    pub(crate) fn with_lobe(&self, visibility: &[T], lobe: &LobeTable<T>, axis: [f64; 3]) -> [T; MAX_COEFFICIENTS] {
        let count = coefficient_count(self.order);
        let mut f = [T::zero(); MAX_COEFFICIENTS];
        f[..count].copy_from_slice(&visibility[..count]);
        add_rotated_zonal(self.order, &lobe.zonal, T::one(), axis.map(T::of), &mut f[..count]);
        f
    }

    /// The visibility terms of the height field and of the blockers apart
    /// ([`PixelPasses`]), given the combined one: each is the combined ratio where the
    /// other occluder set is absent, 1 where its own is; with both, `ratio_of(part, log
    /// vector)` gives the ratio of the height field's log visibility (`T + V_hf = full -
    /// (T + V_blockers) + T`, one horizon march serving both) and of the blockers'.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn split_visibility(
        &self,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        full: &[T],
        unoccluded: &[T],
        visibility: f32,
        mut ratio_of: impl FnMut(OccluderSet, &[T]) -> f32,
    ) -> (f32, f32) {
        let has_heightfield = occluders.horizons.is_some() && self.wedge.is_some();
        match (has_heightfield, occluders.blockers.is_some()) {
            (false, false) => (1.0, 1.0),
            (true, false) => (visibility, 1.0),
            (false, true) => (1.0, visibility),
            (true, true) => {
                let count = coefficient_count(self.order);
                let spheres_only = Occluders { blockers: occluders.blockers, horizons: None, sun_shadows: None };
                let mut blockers = [T::zero(); MAX_COEFFICIENTS];
                let (p, n) = (point.position, point.normal);
                let blockers_only = &mut blockers[..count];
                self.add_visibility_parts(spheres_only, p, n, point.object, caps, blockers_only, None, None);
                let mut heightfield = [T::zero(); MAX_COEFFICIENTS];
                for i in 0..count {
                    heightfield[i] = full[i] - blockers[i] + unoccluded[i];
                }
                (
                    ratio_of(OccluderSet::Heightfield, &heightfield[..count]),
                    ratio_of(OccluderSet::Blockers, &blockers[..count]),
                )
            }
        }
    }

    /// Outgoing radiance of a surface point (docs/design.md, material types). Water is not a
    /// surface material here: the caller shades the reflected point instead.
    /// `caps`: where its sphere caps come from.
    pub fn shade(&self, occluders: Occluders, point: &SurfacePoint, caps: Caps) -> [f32; 3] {
        let (diffuse, glossy) = self.shade_lobes(occluders, point, caps);
        [0, 1, 2].map(|i| diffuse[i] + glossy[i])
    }

    /// [`Self::shade`]'s diffuse and glossy radiance apart, without the visibility terms
    /// that [`Self::shade_passes`] adds: what a pixel whose colour passes tint the two
    /// apart needs.
    pub fn shade_lobes(&self, occluders: Occluders, point: &SurfacePoint, caps: Caps) -> ([f32; 3], [f32; 3]) {
        self.shade_lobes_known(occluders, point, caps, None)
    }

    /// [`Self::shade_lobes`], each sun's horizon taken from `known` where given (marched
    /// with the other pixels of its row: [`Self::suns_along_row`], the same bits).
    pub fn shade_lobes_known(
        &self,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        known: Option<&[KnownAlongSun]>,
    ) -> ([f32; 3], [f32; 3]) {
        let Some((visibility, occlusion)) = self.surface_visibility(occluders, point, caps, None) else {
            return ([0.0; 3], [0.0; 3]);
        };
        let lobes = &self.materials[&point.material];
        let (diffuse, glossy) = self.environment_radiance(occluders, &visibility, &occlusion, lobes, point);
        let (sun_diffuse, sun_glossy) = self.sharp_lit(occluders, point, &lobes.material, &self.suns, true, known).0;
        ([0, 1, 2].map(|i| diffuse[i] + sun_diffuse[i]), [0, 1, 2].map(|i| glossy[i] + sun_glossy[i]))
    }

    /// The log visibility of a surface point, and that of its specular occlusion where
    /// its material has a prefiltered glossy term whose occlusion log-SH gives (in part);
    /// `None` for an unknown material. The horizons marched, into `horizons_found` where
    /// given ([`Self::add_visibility_parts`]).
    pub(crate) fn surface_visibility(
        &self,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        horizons_found: Option<&mut [f32]>,
    ) -> Option<([T; MAX_COEFFICIENTS], [T; MAX_COEFFICIENTS])> {
        let count = coefficient_count(self.order);
        let mut visibility = [T::zero(); MAX_COEFFICIENTS];
        let mut occlusion = [T::zero(); MAX_COEFFICIENTS];
        let lobes = self.materials.get(&point.material);
        let sharp = lobes.is_some_and(|l| l.sharp.as_ref().is_some_and(|sharp| sharp.cone_share < 1.0));
        self.add_visibility_parts(
            occluders,
            point.position,
            point.normal,
            point.object,
            caps,
            &mut visibility[..count],
            sharp.then_some(&mut occlusion[..count]),
            horizons_found,
        );
        lobes.map(|_| (visibility, occlusion))
    }
}

/// Sharp lights' diffuse and specular radiance at a point ([`ShadingKernel::sharp_lit`]).
type SharpLit = ([f32; 3], [f32; 3]);

/// `exp*(lobe)` about +Z as ZH coefficients, exponentiated as the pixels' log vectors
/// are: a zonal function stays zonal, its coefficients the `m = 0` ones.
fn open_lobe<T: Real>(order: usize, exp: &Exponentiator, lobe: &LobeTable<T>) -> Vec<T> {
    let count = coefficient_count(order);
    let mut f = vec![T::zero(); count];
    add_rotated_zonal(order, &lobe.zonal, T::one(), [T::zero(), T::zero(), T::one()], &mut f);
    let mut e = vec![T::zero(); count];
    exp.exp(&f, None, lobe.log_peak, &mut e);
    (0..order).map(|l| e[l * l + l]).collect()
}

/// `max(exp*(lobe about axis) . L, 0)` per colour channel, `open` the lobe's
/// exponentiated ZH about +Z ([`SharpGlossy::open`]): the open lobe's light, the
/// denominator of the specular occlusion.
pub(crate) fn open_lit<T: Real>(order: usize, open: &[T], axis: [f64; 3], light: &[Vec<T>; 3]) -> [T; 3] {
    let count = coefficient_count(order);
    let mut rotated = [T::zero(); MAX_COEFFICIENTS];
    add_rotated_zonal(order, open, T::one(), axis.map(T::of), &mut rotated[..count]);
    light
        .each_ref()
        .map(|light| light.iter().zip(&rotated[..count]).fold(T::zero(), |acc, (&l, &v)| acc + l * v).max(T::zero()))
}

/// log-SH's specular occlusion, `lum(shadowed) / lum(open)` in `[0, 1]`, 1 where the open
/// lobe gets no light.
pub(crate) fn occlusion_ratio<T: Real>(shadowed: [T; 3], open: [T; 3]) -> f64 {
    let lum = |c: [T; 3]| (0..3).map(|i| LUMINANCE[i] * c[i].to_f64().unwrap_or(0.0)).sum::<f64>();
    match lum(open) {
        below if below > 1e-12 => (lum(shadowed) / below).clamp(0.0, 1.0),
        _ => 1.0,
    }
}

/// One of the occluder sets whose visibility term is a pass of its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum OccluderSet {
    Heightfield,
    Blockers,
}

/// `v` in f32, zero-padded to [`MAX_COEFFICIENTS`] (what [`FoldedQuadrature`] reads).
pub(crate) fn as_f32_array<T: Real>(v: &[T]) -> [f32; MAX_COEFFICIENTS] {
    let mut out = [0.0f32; MAX_COEFFICIENTS];
    for (o, x) in out.iter_mut().zip(v) {
        *o = x.to_f32().unwrap_or(0.0);
    }
    out
}

/// Whether the kernel's scalar is f32 (the throughput path) rather than the f64 oracle.
fn is_f32<T: Real>() -> bool {
    std::any::TypeId::of::<T>() == std::any::TypeId::of::<f32>()
}

// The same shading split into compositing passes and visibility terms (`logsh render`).
mod lit;
pub(crate) use lit::open_corrected_channel;
mod pixel_passes;
mod transfer;
pub(crate) use pixel_passes::ratio as visibility_ratio;
pub use pixel_passes::{PixelPasses, LUMINANCE};
pub use transfer::{GlossyTransfer, PointTransfer};
