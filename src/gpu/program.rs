//! The shading program of one frame: which features the scene needs, the WGSL source
//! composed for them, and the tables it reads, all generated from the CPU kernel's own
//! tables (one math definition, two executors).
//!
//! Specialisation: the source holds only the modules the scene uses, and the blocks of
//! `shaders/shade.wgsl` between `//#if FEATURE` and `//#endif` are dropped when the
//! feature is absent, so a scene without a height field carries no march, one without
//! blockers no cap loop, one without Phong materials no second exponentiation. The order,
//! W and the table offsets are constants of the source, so loops have fixed trip counts
//! and there is no per-pixel cost for choosing them at run time. Pipelines are cached by
//! source text: a sequence compiles once.

use super::layout::{
    wgsl_declarations, wgsl_table_loaders, GpuLevel, GpuLobeHead, GpuMaterial, GpuPointLamp, GpuShadowMap, GpuSun,
    TableRecord, MATERIAL_DIFFUSE, MATERIAL_PHONG, NO_MAP,
};
use crate::heightfield::{HorizonSettings, LevelReconstruction, PyramidPlan, ScaleMax};
use crate::logsh::cap_scale;
use crate::scene::Material;
use crate::sh::basis::{coefficient_count, double_factorial_odd, funk_hecke_factor, nlp_scale, real_normalisation};
use crate::sh::exp::{ol_node_count, HYB_MAX_SQUARINGS, OL_COARSE_STEP, OL_FINE_NODES, ONE_DC, SERIES_MAX_TERMS, Y0};
use crate::sh::{ExpMethod, SeparableQuadrature};
use crate::shade::glossy::{Prefiltered, SharpLobe, ALBEDO_ENTRIES};
use crate::shade::kernel::{sh_space_max_magnitude, LUMINANCE, SH_SPACE_BLEND};
use crate::shade::sun::{disk_pattern, patch_radius, DISK_DIRECTIONS};
use crate::shade::sun_shadow::{drift_per_depth, ShadowMapMarch, SunShadows, MAX_STEPS, MINIMA_LEVELS};
use crate::shade::{FrameContents, ShadingKernel};
use std::collections::BTreeMap;
use std::sync::Arc;

const SH_WGSL: &str = include_str!("../../shaders/sh.wgsl");
const LOGSH_WGSL: &str = include_str!("../../shaders/logsh.wgsl");
const HEIGHTFIELD_WGSL: &str = include_str!("../../shaders/heightfield.wgsl");
const EXP_QUAD_WGSL: &str = include_str!("../../shaders/exp_quad.wgsl");
const EXP_OL_WGSL: &str = include_str!("../../shaders/exp_ol.wgsl");
const EXP_PRODUCT_WGSL: &str = include_str!("../../shaders/exp_product.wgsl");
const DISK_WGSL: &str = include_str!("../../shaders/disk.wgsl");
const SHADE_WGSL: &str = include_str!("../../shaders/shade.wgsl");
/// The pyramid pre-pass (fixed source: it depends on no setting).
pub const PYRAMID_WGSL: &str = include_str!("../../shaders/pyramid.wgsl");

/// What a frame's shading pass contains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Features {
    /// What the frame holds (height field, blockers, Phong materials).
    pub contents: FrameContents,
    /// How far the program is specialised; less than [`Specialisation::Full`] only to
    /// measure what specialisation saves (`logsh bench --specialise`).
    pub specialisation: Specialisation,
    /// The visibility terms of `logsh render`'s compositing passes (three more diffuse
    /// exponentiations per point; src/shade/kernel/pixel_passes.rs).
    pub passes: bool,
    /// The visibility grid's block size ([`crate::shade::visibility_grid`]): 1 computes
    /// visibility at every point; above 1, a pre-pass computes it per block and each point
    /// interpolates it.
    pub grid: usize,
}

/// The feature names the `//#if` blocks of `shaders/` test.
const FLAG_NAMES: [&str; 11] = [
    "HEIGHTFIELD",
    "BLOCKERS",
    "PHONG",
    "PREFILTERED",
    "SUNS",
    "EXP_QUAD",
    "EXP_OL",
    "EXP_HYB",
    "EXP_SERIES",
    "PASSES",
    "GRID",
];

impl Features {
    fn flags(&self, exp: ExpMethod) -> Vec<(&'static str, bool)> {
        let all = self.specialisation != Specialisation::Full;
        let on = [
            self.contents.heightfield || all,
            self.contents.blockers || all,
            self.contents.phong || all,
            self.contents.prefiltered || all,
            self.contents.suns || all,
            matches!(exp, ExpMethod::Quad | ExpMethod::Exact),
            exp == ExpMethod::Ol,
            exp == ExpMethod::Hyb,
            exp == ExpMethod::Series,
            self.passes,
            self.grid > 1,
        ];
        FLAG_NAMES.into_iter().zip(on).collect()
    }
}

/// What a program is specialised to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Specialisation {
    /// The scene's features and the order: what shading runs.
    Full,
    /// The order only: every feature compiled in and skipped by a uniform branch when the
    /// frame lacks it (what a program serving every scene would carry).
    Order,
    /// Neither: every feature compiled in, arrays sized for order 8 and loop bounds read
    /// from uniforms (one program for every scene and order).
    None,
}

/// The height-field march's shape, which fixes the shader's loop bounds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct MarchShape {
    pub directions: usize,
    /// Levels whose receiver term the march reads.
    pub levels: usize,
    pub steps: usize,
    pub bspline_levels: bool,
    pub bspline_scale_max: bool,
}

impl MarchShape {
    pub fn of(plan: &PyramidPlan, horizon: &HorizonSettings) -> Self {
        Self {
            directions: plan.directions.len(),
            levels: plan.steps.last().map_or(1, |s| s.level + 1),
            steps: plan.steps.len(),
            bspline_levels: horizon.reconstruction == LevelReconstruction::BicubicBSpline,
            bspline_scale_max: horizon.scale_max == ScaleMax::BSpline,
        }
    }
}

/// The record of one block of the visibility grid in the pre-pass's buffer
/// (`shaders/shade.wgsl`, `grid_visibility`): a header of [`Self::HEADER`] values (the
/// block's point, the bits of its object, its normal, 1 where it has a surface pixel),
/// then the tangents of its horizons' elevations, its caps' log vector and the height
/// field's log vector with the block's tangent plane folded in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VisibilityBlocks {
    /// Azimuths (0 without a height field or a grid).
    pub horizons: usize,
    /// Coefficients (0 without blockers or a grid).
    pub caps: usize,
    /// Coefficients of the height field's log vector (0 without a height field or a grid).
    pub field: usize,
}

impl VisibilityBlocks {
    pub const HEADER: usize = 8;

    pub fn of(kernel: &ShadingKernel<f32>, features: Features, march: Option<MarchShape>) -> Self {
        if features.grid <= 1 {
            return Self::default();
        }
        Self {
            horizons: march.map_or(0, |m| m.directions),
            caps: if features.contents.blockers { coefficient_count(kernel.order) } else { 0 },
            field: if march.is_some() { coefficient_count(kernel.order) } else { 0 },
        }
    }

    /// Values per block.
    pub fn stride(&self) -> usize {
        Self::HEADER + self.horizons + self.caps + self.field
    }
}

/// Named offsets into one flat `f32` table buffer; integers are stored as their bits.
#[derive(Default)]
struct TableBuilder {
    data: Vec<f32>,
    offsets: Vec<(&'static str, usize)>,
}

impl TableBuilder {
    fn push(&mut self, name: &'static str, values: impl IntoIterator<Item = f32>) -> usize {
        let offset = self.data.len();
        self.offsets.push((name, offset));
        self.data.extend(values);
        offset
    }

    fn push_unnamed(&mut self, values: impl IntoIterator<Item = f32>) -> usize {
        let offset = self.data.len();
        self.data.extend(values);
        offset
    }
}

/// Every input of the shading pass that does not change per pixel.
pub struct ShadeProgram {
    /// The composed WGSL.
    pub source: String,
    pub features: Features,
    /// The `f32` tables, offsets baked into `source`.
    pub tables: Vec<f32>,
    /// Material slots, and the slot of each material index the scene declares.
    pub materials: Vec<GpuMaterial>,
    pub slots: BTreeMap<u32, u32>,
    /// The exponentiation's quadrature grid.
    pub quadrature: QuadratureGrid,
    /// The visibility grid's block records (empty without a grid).
    pub blocks: VisibilityBlocks,
    order: usize,
    exp: ExpMethod,
    march: Option<MarchShape>,
    tensor_entries: usize,
    /// Suns and point lamps: each a disk per pixel.
    suns: usize,
}

impl ShadeProgram {
    /// Generates the program from the CPU kernel's tables. `march` is `Some` when the
    /// frame has a height field. The frame's shadow maps go last in the tables, so that
    /// the offsets the source bakes in stay the same from frame to frame.
    pub fn new(
        kernel: &ShadingKernel<f32>,
        features: Features,
        march: Option<MarchShape>,
        sun_shadows: &SunShadows,
    ) -> Self {
        let tables = ProgramTables::build(kernel, march, sun_shadows);
        let source = compose_source(kernel, features, march, &tables);
        Self {
            source,
            features,
            tables: tables.builder.data,
            materials: tables.materials,
            slots: tables.slots,
            quadrature: tables.quadrature,
            blocks: VisibilityBlocks::of(kernel, features, march),
            order: kernel.order,
            exp: kernel.exp.method,
            march,
            tensor_entries: kernel.exp.tensor.as_ref().map_or(0, |t| t.entry_count()),
            suns: kernel.suns.len() + kernel.points.len(),
        }
    }
}

/// The tables of a program, each from the module that owns its math.
struct ProgramTables {
    builder: TableBuilder,
    materials: Vec<GpuMaterial>,
    slots: BTreeMap<u32, u32>,
    quadrature: QuadratureGrid,
}

/// The shape of the exponentiation's quadrature grid ([`SeparableQuadrature`]).
#[derive(Clone, Copy, Debug)]
pub struct QuadratureGrid {
    pub rows: usize,
    pub azimuths: usize,
}

impl ProgramTables {
    fn build(kernel: &ShadingKernel<f32>, march: Option<MarchShape>, sun_shadows: &SunShadows) -> Self {
        let order = kernel.order;
        let mut t = TableBuilder::default();

        // The basis and rotation constants (src/sh/basis.rs) and the cap's 2 pi K_l
        // (src/logsh/cap.rs).
        t.push(
            "T_SH_NORMALISATION",
            (0..order).flat_map(|l| (-(l as i64)..=l as i64).map(move |m| real_normalisation(l, m) as f32)),
        );
        t.push("T_DOUBLE_FACTORIAL", (0..order).map(|m| double_factorial_odd(m) as f32));
        t.push("T_FUNK_HECKE", (0..order).map(|l| funk_hecke_factor(l) as f32));
        t.push("T_NLP_SCALE", (0..order).map(|l| nlp_scale(l) as f32));
        t.push("T_CAP_SCALE", (0..order).map(|l| cap_scale(l) as f32));
        // Each cap's log depth per angular radius and each horizon band's per width
        // (src/shade/fitted_depth.rs).
        t.push("T_CAP_DEPTH", kernel.cap_depths.iter().copied());
        t.push("T_BAND_DEPTH", kernel.band_depths.iter().copied());
        t.push("T_BAND_COVERAGE", kernel.band_coverages.iter().map(|&c| c as f32));

        // Lobes: order log-ZH values then the log of the peak.
        t.push("T_TANGENT", kernel.tangent.iter().copied());
        // The height field's slices at the horizontal, which the specular occlusion takes
        // out (kernel.rs, below_horizontal_slices); empty without a height field.
        t.push("T_BELOW_HORIZONTAL", kernel.below_horizontal_slices.iter().copied());
        t.push("T_DIFFUSE", kernel.diffuse.zonal.iter().copied().chain([kernel.diffuse.log_peak as f32]));
        // The open receiver's diffuse light in full (kernel.rs, OpenIrradiance): the
        // light's order-8 coefficients weighted by the rotated cosine, R then G then B, the
        // basis factors up to order 8, and exp*(T + D) as ZH.
        let eight = crate::shade::kernel::IRRADIANCE_ORDER;
        let weighted = kernel.irradiance.as_ref().map(|irradiance| irradiance.weighted_light());
        t.push("T_IRRADIANCE", weighted.iter().flat_map(|w| w.iter().flatten().map(|&v| v as f32)));
        t.push(
            "T_IRRADIANCE_NORMALISATION",
            (0..eight).flat_map(|l| (-(l as i64)..=l as i64).map(move |m| real_normalisation(l, m) as f32)),
        );
        t.push("T_IRRADIANCE_FACTORIAL", (0..eight).map(|m| double_factorial_odd(m) as f32));
        t.push("T_DIFFUSE_OPEN", kernel.diffuse_open.iter().copied());
        // The caps' hidden detail (src/shade/cap_detail.rs), empty without it.
        t.push("T_CAP_DETAIL", kernel.cap_detail.iter().flat_map(|table| table.values()));
        let (materials, slots) = material_slots(kernel, &mut t);
        // The disk pattern (x, then y), the suns (src/shade/sun.rs) and the point lamps
        // (src/scene/light.rs, PointLight).
        let pattern = disk_pattern();
        t.push("T_DISK", pattern.iter().map(|p| p[0] as f32).chain(pattern.iter().map(|p| p[1] as f32)));
        let suns_at = t.push(
            "T_SUNS",
            kernel.suns.iter().flat_map(|sun| {
                let (d, i) = (sun.light.direction, sun.disk_integral);
                let one_minus_cos = 1.0 - sun.light.half_angle.cos();
                GpuSun {
                    axis: [d[0], d[1], d[2], one_minus_cos].map(|v| v as f32),
                    integral: [i[0], i[1], i[2], sun.disk.patch].map(|v| v as f32),
                    shadow_map: NO_MAP,
                    drift: drift_per_depth(sun.light.half_angle) as f32,
                    ..Default::default()
                }
                .floats()
            }),
        );
        t.push(
            "T_POINTS",
            kernel.points.iter().flat_map(|lamp| {
                let [x, y, z] = lamp.position;
                let i = lamp.color.map(|c| f64::from(lamp.power) * f64::from(c) / (4.0 * std::f64::consts::PI));
                let soft = if lamp.soft_falloff { 1.0 } else { 0.0 };
                GpuPointLamp {
                    position: [x, y, z, lamp.radius].map(|v| v as f32),
                    intensity: [i[0], i[1], i[2], soft].map(|v| v as f32),
                }
                .floats()
            }),
        );

        // The light, channel-major, and the exponentiation's tables (src/sh/exp.rs).
        let quadrature = push_exponentiation(kernel, &mut t);
        push_wedge(kernel, march, &mut t);
        push_sun_shadows(kernel, sun_shadows, suns_at, &mut t);
        if t.data.is_empty() {
            t.data.push(0.0);
        }
        Self { builder: t, materials, slots, quadrature }
    }
}

/// Each sun's shadow map where the frame has one ([`SunShadows::of_sun`], as the CPU
/// picks it): its [`GpuShadowMap`], its levels' [`GpuLevel`]s, their minima and `Zfar`,
/// its offset written into the sun's record at `suns_at`. Suns that one map serves (a Sun
/// lamp along an HDRI's sun) share its tables.
fn push_sun_shadows(kernel: &ShadingKernel<f32>, sun_shadows: &SunShadows, suns_at: usize, t: &mut TableBuilder) {
    let field = std::mem::offset_of!(GpuSun, shadow_map) / 4;
    let record = std::mem::size_of::<GpuSun>() / 4;
    let level_record = std::mem::size_of::<GpuLevel>() / 4;
    // Maps already in the tables, and where.
    let mut pushed: Vec<(*const ShadowMapMarch, usize)> = Vec::new();
    for (s, sun) in kernel.suns.iter().enumerate() {
        let Some(march) = sun_shadows.of_sun(sun.disk.axis) else { continue };
        if let Some(&(_, at)) = pushed.iter().find(|(m, _)| std::ptr::eq(*m, march)) {
            t.data[suns_at + s * record + field] = f32::from_bits(at as u32);
            continue;
        }
        let map = &march.map;
        let levels = march.level_count();
        let at = t.data.len();
        // The head, the level records, each level's minima, then `Zfar`.
        let mut minima_at = at + std::mem::size_of::<GpuShadowMap>() / 4 + level_record * levels;
        let mut records = Vec::new();
        for k in 0..levels {
            let (columns, rows, minima) = march.level(k);
            let record = GpuLevel { offset: minima_at as u32, columns: columns as u32, rows: rows as u32, pad: 0 };
            records.extend(record.floats());
            minima_at += minima.len();
        }
        let head = GpuShadowMap {
            axis: [map.axis[0], map.axis[1], map.axis[2], map.texel()].map(|v| v as f32),
            origin: [map.origin[0], map.origin[1], map.origin[2], f64::from(march.shallowest())].map(|v| v as f32),
            right: [map.right[0], map.right[1], map.right[2], map.size[0]].map(|v| v as f32),
            up: [map.up[0], map.up[1], map.up[2], map.size[1]].map(|v| v as f32),
            columns: map.columns as u32,
            rows: map.rows as u32,
            levels: levels as u32,
            far: minima_at as u32,
        };
        t.push_unnamed(head.floats().into_iter().chain(records));
        for k in 0..levels {
            t.push_unnamed(march.level(k).2.iter().copied());
        }
        t.push_unnamed(map.far_depths.iter().copied());
        t.data[suns_at + s * record + field] = f32::from_bits(at as u32);
        pushed.push((march, at));
    }
}

/// The material slots and the Phong lobes they point to, and the slot of each material
/// index the scene declares. Water is never shaded itself (its pixels are the reflected
/// points), so it has no slot.
fn material_slots(kernel: &ShadingKernel<f32>, t: &mut TableBuilder) -> (Vec<GpuMaterial>, BTreeMap<u32, u32>) {
    let mut materials = Vec::new();
    let mut slots = BTreeMap::new();
    // Prefiltered maps already in the tables (materials of one lobe share theirs).
    let mut maps: Vec<(*const Prefiltered, u32)> = Vec::new();
    for (&index, lobes) in &kernel.materials {
        let (albedo, specular, kind, phong_lobe) = match (&lobes.material, &lobes.phong) {
            (Material::Phong { albedo, specular, .. }, Some(lobe)) => {
                let offset = t.push_unnamed(lobe.zonal.iter().copied().chain([lobe.log_peak as f32]));
                (*albedo, *specular, MATERIAL_PHONG, offset as u32)
            }
            (Material::Diffuse { albedo } | Material::Heightfield { albedo }, _) => {
                (*albedo, [0.0; 3], MATERIAL_DIFFUSE, 0)
            }
            _ => continue,
        };
        // The glossy lobe (shaders/shade.wgsl, lobe_kind): its shape, width, core radius
        // and cone share; for a prefiltered one also the cone's weights, the albedo table,
        // the sharp lights' scale table and the open lobe's ZH, and its map.
        let (sharp_map, sharp_tables) = match (&lobes.material, &lobes.sharp) {
            (_, Some(sharp)) => {
                let key = Arc::as_ptr(&sharp.prefiltered);
                let map = match maps.iter().find(|(k, _)| *k == key) {
                    Some(&(_, offset)) => offset,
                    None => {
                        // The texels the frame's plan computed (FramePlan::new); the shader
                        // reads no other.
                        let m = &sharp.prefiltered;
                        let header = [f32::from_bits(m.width as u32), f32::from_bits(m.height as u32)];
                        let texels = m.computed_texels();
                        let offset = t.push_unnamed(header.into_iter().chain(texels.iter().flatten().copied()));
                        maps.push((key, offset as u32));
                        offset as u32
                    }
                };
                let (kind, width) = match sharp.lobe {
                    SharpLobe::Ggx { alpha } => (LOBE_GGX, alpha),
                    SharpLobe::Phong { exponent } => (LOBE_PHONG, exponent),
                };
                let core = sharp.lobe.core_radius();
                let head = GpuLobeHead {
                    kind,
                    width: width as f32,
                    core_one_minus_cos: (1.0 - core.cos()) as f32,
                    core_patch: patch_radius(core) as f32,
                    cone_share: sharp.cone_share as f32,
                    lamp_fresnel: sharp.lamp_fresnel as f32,
                };
                let weights = sharp.cone_weights.map(|w| w as f32);
                let tables = t.push_unnamed(
                    head.floats()
                        .into_iter()
                        .chain(weights)
                        .chain(sharp.albedo.iter().copied())
                        .chain(sharp.lamp_scale.iter().copied())
                        .chain(sharp.open.iter().copied())
                        .chain(sharp.share_above.iter().copied()),
                );
                (map, tables as u32)
            }
            (Material::Phong { exponent, .. }, None) => {
                let head = GpuLobeHead { kind: LOBE_SH, width: *exponent, ..Default::default() };
                (NO_MAP, t.push_unnamed(head.floats()) as u32)
            }
            _ => (NO_MAP, 0),
        };
        slots.insert(index, materials.len() as u32);
        materials.push(GpuMaterial {
            albedo: [albedo[0], albedo[1], albedo[2], 0.0],
            specular: [specular[0], specular[1], specular[2], 0.0],
            kind,
            phong_lobe,
            sharp_map,
            sharp_tables,
        });
    }
    if materials.is_empty() {
        materials.push(GpuMaterial::default());
    }
    (materials, slots)
}

/// The glossy lobe shapes of the material tables (`lobe_kind` in shaders/shade.wgsl).
const LOBE_GGX: u32 = 0;
const LOBE_PHONG: u32 = 1;
const LOBE_SH: u32 = 2;

/// The light and the tables of the kernel's exponentiation; returns the shape of the
/// quadrature grid, which the program sums in separable form ([`SeparableQuadrature`]).
fn push_exponentiation(kernel: &ShadingKernel<f32>, t: &mut TableBuilder) -> QuadratureGrid {
    let light = &kernel.light;
    t.push("T_LIGHT", light.iter().flat_map(|channel| channel.iter().copied()));
    let quadrature = kernel.exp.exact.as_ref().expect("every exponentiator carries its quadrature");
    let light_f64 = light.clone().map(|channel| channel.iter().map(|&v| f64::from(v)).collect());
    let separable = SeparableQuadrature::new(quadrature, &light_f64);
    t.push("T_QUAD_ROWS", separable.row_factors.iter().copied());
    t.push("T_QUAD_AZIMUTHS", separable.azimuth_cos_sin.iter().flatten().copied());
    t.push("T_NODE_LIGHT", separable.node_light.iter().flatten().copied());
    let grid = QuadratureGrid { rows: separable.rows, azimuths: separable.azimuths };
    let ol = kernel.exp.ol.as_ref();
    t.push("T_OL_A", ol.map(|table| table.a.iter().map(|&a| a as f32).collect::<Vec<_>>()).unwrap_or_default());
    t.push("T_OL_B", ol.map(|table| table.b.iter().map(|&b| b as f32).collect::<Vec<_>>()).unwrap_or_default());
    let (rows, entries) = match kernel.exp.tensor.as_ref() {
        Some(tensor) => {
            let mut rows = vec![0u32];
            let mut entries = Vec::new();
            for row in tensor.rows() {
                for &(j, k, gamma) in row {
                    entries.push(f32::from_bits(u32::from(j) | (u32::from(k) << 16)));
                    entries.push(gamma as f32);
                }
                rows.push((entries.len() / 2) as u32);
            }
            (rows.into_iter().map(f32::from_bits).collect(), entries)
        }
        None => (Vec::new(), Vec::new()),
    };
    t.push("T_TENSOR_ROWS", rows);
    t.push("T_TENSOR_ENTRIES", entries);
    grid
}

/// The height field's wedge operator, z-rotation phases and azimuths
/// (src/logsh/wedge.rs, src/heightfield/pyramid.rs); empty without a height field.
fn push_wedge(kernel: &ShadingKernel<f32>, march: Option<MarchShape>, t: &mut TableBuilder) {
    let order = kernel.order;
    let directions = march.map_or(0, |m| m.directions);
    let Some(wedge) = &kernel.wedge else {
        for name in ["T_WEDGE", "T_PHASES", "T_AZIMUTHS"] {
            t.push(name, []);
        }
        return;
    };
    t.push("T_WEDGE", wedge.matrix.iter().map(|&m| m as f32));
    let dphi = wedge.wedge_width();
    t.push(
        "T_PHASES",
        (0..directions).flat_map(|k| {
            (0..order).flat_map(move |m| {
                let angle = (m * k) as f64 * dphi;
                [angle.cos() as f32, angle.sin() as f32]
            })
        }),
    );
    t.push(
        "T_AZIMUTHS",
        (0..directions).flat_map(|k| {
            let phi = std::f64::consts::TAU * k as f64 / directions as f64;
            [phi.cos() as f32, phi.sin() as f32]
        }),
    );
}

/// A constant of the generated prelude.
enum Constant {
    U32(usize),
    F32(f64),
    Bool(bool),
    Vec3([f64; 3]),
}

impl Constant {
    fn declare(&self, name: &str) -> String {
        match self {
            Constant::U32(v) => format!("const {name}: u32 = {v}u;\n"),
            Constant::F32(v) => format!("const {name}: f32 = {};\n", wgsl_float(*v)),
            Constant::Bool(v) => format!("const {name}: bool = {v};\n"),
            Constant::Vec3(v) => {
                let [x, y, z] = v.map(wgsl_float);
                format!("const {name}: vec3<f32> = vec3<f32>({x}, {y}, {z});\n")
            }
        }
    }
}

/// The constants every module reads: the order and loop bounds, the march's shape, the
/// switches, and the exponentiation's limits (each from the module that defines it).
fn prelude(
    kernel: &ShadingKernel<f32>,
    features: Features,
    march: Option<MarchShape>,
    grid: QuadratureGrid,
    blocks: VisibilityBlocks,
) -> String {
    use Constant::*;
    let order = kernel.order;
    let march = march.unwrap_or_default();
    let generic = features.specialisation != Specialisation::Full;
    let order_cap = if features.specialisation == Specialisation::None { crate::sh::MAX_ORDER } else { order };
    let constants = [
        ("ORDER", U32(order)),
        ("ORDER_CAP", U32(order_cap)),
        ("ORDER_PLUS_ONE", U32(order_cap + 1)),
        ("COUNT", U32(coefficient_count(order))),
        // Coefficient arrays hold a multiple of 4 entries (the padding stays 0).
        ("COUNT_CAP", U32(coefficient_count(order_cap).div_ceil(4) * 4)),
        ("QUAD_ROWS", U32(grid.rows)),
        ("QUAD_AZIMUTHS", U32(grid.azimuths)),
        ("DIRECTIONS", U32(march.directions.max(1))),
        ("LEVELS", U32(march.levels.max(1))),
        ("STEPS", U32(march.steps)),
        ("STEP_ARRAY", U32(march.steps.max(1))),
        ("BSPLINE_LEVELS", Bool(march.bspline_levels)),
        ("BSPLINE_SCALE_MAX", Bool(march.bspline_scale_max)),
        ("GENERIC", Bool(generic)),
        ("TANGENT_OCCLUSION", Bool(kernel.tangent_occlusion)),
        ("RATIO_ATTENUATION", Bool(kernel.ratio_attenuation)),
        ("DEPTH_INTERVALS", U32(crate::shade::fitted_depth::DEPTH_INTERVALS)),
        ("BAND_ROWS", U32(kernel.band_coverages.len())),
        ("OVERLAP_FLOOR", Bool(kernel.overlap_floor)),
        ("IRRADIANCE", Bool(kernel.irradiance.is_some())),
        ("CAP_DETAIL", Bool(kernel.cap_detail.is_some())),
        ("CAP_DETAIL_COLUMNS", U32(crate::shade::cap_detail::COLUMNS)),
        ("CAP_DETAIL_ROWS", U32(crate::shade::cap_detail::ROWS)),
        ("CAP_DETAIL_RADII", U32(crate::shade::cap_detail::RADII)),
        ("CAP_DETAIL_MAX_RADIUS", F32(crate::shade::cap_detail::MAX_RADIUS)),
        ("CAP_DETAIL_MIN_RATIO", F32(crate::shade::cap_detail::MIN_RATIO)),
        ("IRRADIANCE_ORDER", U32(crate::shade::kernel::IRRADIANCE_ORDER)),
        ("OPEN_LIGHT_FLOOR", F32(crate::shade::kernel::OPEN_LIGHT_FLOOR)),
        ("GROUND", Bool(kernel.ground.is_some())),
        ("SKY_ONLY", Bool(kernel.sky_only)),
        ("GROUND_HEIGHT", F32(kernel.ground.unwrap_or(0.0))),
        ("OWN_SPHERE_REACH", F32(crate::logsh::OWN_SPHERE_REACH)),
        ("NEGLIGIBLE_RATIO", F32(crate::shade::blocker_tree::NEGLIGIBLE_RATIO)),
        ("BEHIND_TOLERANCE", F32(crate::shade::blocker_tree::BEHIND_TOLERANCE)),
        ("Y0", F32(Y0)),
        ("ONE_DC", F32(ONE_DC)),
        ("OL_FINE_NODES", U32(OL_FINE_NODES)),
        ("OL_COARSE_STEP", F32(OL_COARSE_STEP)),
        ("OL_NODES", U32(ol_node_count())),
        ("HYB_MAX_SQUARINGS", U32(HYB_MAX_SQUARINGS as usize)),
        ("SERIES_MAX_TERMS", U32(SERIES_MAX_TERMS)),
        ("SERIES_TOLERANCE", F32(f64::from(f32::EPSILON) * 0.01)),
        ("SH_SPACE_MAX_MAGNITUDE", F32(sh_space_max_magnitude(kernel.exp.method))),
        ("SH_SPACE_BLEND", F32(SH_SPACE_BLEND)),
        ("LUMINANCE", Vec3(LUMINANCE)),
        ("ALBEDO_ENTRIES", U32(ALBEDO_ENTRIES)),
        ("DISK_DIRECTIONS", U32(DISK_DIRECTIONS)),
        ("DISK_QUADS", U32(DISK_DIRECTIONS / 4)),
        ("SUN_COUNT", U32(kernel.suns.len())),
        ("MAP_MAX_STEPS", U32(MAX_STEPS)),
        ("POINT_COUNT", U32(kernel.points.len())),
        ("POINT_HALF_ANGLE_MIN", F32(crate::scene::light::POINT_HALF_ANGLE_MIN)),
        ("POINT_NEAREST", F32(crate::scene::light::POINT_NEAREST)),
        ("LOBE_GGX", U32(LOBE_GGX as usize)),
        ("SMOOTH_OVER_DISK", F32(crate::shade::glossy::SMOOTH_OVER_DISK)),
        ("DIELECTRIC_F0", F32(crate::shade::glossy::DIELECTRIC_F0)),
        ("METAL_F0", F32(crate::shade::glossy::METAL_F0)),
        ("LOBE_PHONG", U32(LOBE_PHONG as usize)),
        ("LOBE_SH", U32(LOBE_SH as usize)),
        ("GRID_SIZE", U32(features.grid.max(1))),
        ("GRID_HEADER", U32(VisibilityBlocks::HEADER)),
        ("GRID_HORIZONS", U32(blocks.horizons)),
        ("GRID_CAPS", U32(blocks.caps)),
        ("GRID_FIELD", U32(blocks.field)),
        ("GRID_STRIDE", U32(blocks.stride())),
        ("GRID_MIN_WEIGHT", F32(crate::shade::visibility_grid::MIN_WEIGHT)),
        ("GRID_NORMAL_POWER", F32(f64::from(crate::shade::visibility_grid::NORMAL_POWER))),
        ("GRID_PLANE_WIDTH", F32(crate::shade::visibility_grid::PLANE_WIDTH)),
        ("GRID_FIELD_NEAR", F32(crate::shade::visibility_grid::FIELD_NORMAL_COSINES[0])),
        ("GRID_FIELD_FAR", F32(crate::shade::visibility_grid::FIELD_NORMAL_COSINES[1])),
    ];
    constants.iter().map(|(name, value)| value.declare(name)).collect()
}

/// The WGSL of a program: the shared declarations, the prelude, the table offsets, and
/// the modules the features need with their inactive blocks removed.
fn compose_source(
    kernel: &ShadingKernel<f32>,
    features: Features,
    march: Option<MarchShape>,
    tables: &ProgramTables,
) -> String {
    let exp = kernel.exp.method;
    let blocks = VisibilityBlocks::of(kernel, features, march);
    let mut source =
        wgsl_declarations() + &wgsl_table_loaders() + &prelude(kernel, features, march, tables.quadrature, blocks);
    for (name, offset) in &tables.builder.offsets {
        source += &Constant::U32(*offset).declare(name);
    }
    let flags = features.flags(exp);
    let mut modules = vec![SH_WGSL, EXP_QUAD_WGSL];
    if matches!(exp, ExpMethod::Ol | ExpMethod::Hyb) {
        modules.push(EXP_OL_WGSL);
    }
    if matches!(exp, ExpMethod::Hyb | ExpMethod::Series) {
        modules.push(EXP_PRODUCT_WGSL);
    }
    if flag(&flags, "BLOCKERS") {
        modules.push(LOGSH_WGSL);
    }
    if flag(&flags, "HEIGHTFIELD") {
        modules.push(HEIGHTFIELD_WGSL);
    }
    if flag(&flags, "PREFILTERED") || flag(&flags, "SUNS") {
        modules.push(DISK_WGSL);
    }
    modules.push(SHADE_WGSL);
    let runtime_order = features.specialisation == Specialisation::None;
    for module in modules {
        let module = preprocess(module, &flags).expect("the shaders test only the features of FLAG_NAMES");
        source += &if runtime_order { runtime_bounds(&module) } else { module };
    }
    source
}

impl ShadeProgram {
    /// An upper bound on the loop iterations one invocation of the shading pass runs, for
    /// a Phong point seeing every blocker: lavapipe (Mesa's CPU Vulkan driver, through
    /// at least Mesa 22.3) ends an invocation's loops after 65535 iterations in all, so a
    /// program above [`LAVAPIPE_LOOP_LIMIT`] would silently shade a wrong image there.
    pub fn loop_iterations(&self, spheres: usize) -> u64 {
        let n = self.order as u64;
        let c = n * n;
        let eval_basis = n + n * (n + 1) / 2;
        let add_rotated = eval_basis + n + c;
        // Per row, C and S of f (and of the visibility, with the overlap floor, in the
        // same loops); per node, Clenshaw's recurrence over m.
        let QuadratureGrid { rows, azimuths } = self.quadrature;
        let quad = rows as u64 * (n + n * (n + 1) / 2 + azimuths as u64 * n);
        let product = c + self.tensor_entries as u64;
        // SH-space methods blend into the quadrature near their range's end (both run).
        let exp = match self.exp {
            ExpMethod::Quad | ExpMethod::Exact => quad,
            ExpMethod::Ol => quad + 3 * c,
            // Below the hand-over, at most 7 squarings.
            ExpMethod::Hyb => quad + 3 * c + 7 * product,
            ExpMethod::Series => quad + 3 * c + SERIES_MAX_TERMS as u64 * (product + c),
        };
        let lit = n + add_rotated + exp;
        let tangent = n + add_rotated;
        // The blocker tree has 2 spheres - 1 nodes. Lanes that walk it in lockstep (lavapipe
        // runs 8 invocations per SIMD thread) take different paths, and a cap's loops run
        // at every step where any lane adds one: measured, a frame whose lanes each add far
        // fewer caps than there are nodes still ran into the limit. So every node counts as
        // a cap.
        let sphere = 2 * (1 + 2 * n + add_rotated);
        let heightfield = self.march.map_or(0, |m| {
            let sample = if m.bspline_levels { 21 } else { 1 };
            let steps = m.steps as u64;
            let horizon = steps * (1 + sample) + if m.bspline_scale_max { steps } else { 0 };
            let wedge = c * (1 + n) + n * (n + 1) / 2 + c;
            // A banded slice: two NLP slices (Legendre and coefficients, 2n each) and
            // their combination (n).
            let slice = 5 * n;
            // The receiver terms per level, the step ceilings, then per azimuth.
            m.levels as u64 * (1 + sample) + steps + m.directions as u64 * (1 + horizon + slice + wedge) + wedge
        });
        let passes = if self.features.passes { 2 * tangent + 3 * lit + n } else { 0 };
        // A disk of directions (shaders/disk.wgsl): its setup and planes, one azimuth's
        // march, and every node of the tree updating the directions four at a time.
        let quads = (DISK_DIRECTIONS / 4) as u64;
        let march_one = self.march.map_or(0, |m| {
            let sample = if m.bspline_levels { 21 } else { 1 };
            m.levels as u64 * (1 + sample) + m.steps as u64 * (3 + sample)
        });
        let disk = 4 * quads + march_one + 2 * spheres as u64 * (1 + quads);
        // The specular occlusion: its cone, its own height-field march, the open lobe.
        let prefiltered =
            if self.features.contents.prefiltered { disk + quads + heightfield + add_rotated + c } else { 0 };
        // A shadow map's march (shaders/disk.wgsl, shadow_blocked): its footprint's levels,
        // then every direction's steps.
        let map = MINIMA_LEVELS as u64 + DISK_DIRECTIONS as u64 * (1 + MAX_STEPS as u64);
        let suns = self.suns as u64 * (disk + quads + map);
        // The grid's four blocks, read and weighed; a point no block is like is computed
        // alone, so the march and the caps above stay in the bound (the pre-pass runs
        // fewer: one point's march and caps).
        let grid = if self.features.grid > 1 {
            let values = (self.blocks.horizons + self.blocks.caps + self.blocks.field) as u64;
            4 * (1 + values) + values
        } else {
            0
        };
        1 + tangent + heightfield + spheres as u64 * sphere + 2 * lit + passes + prefiltered + suns + grid
    }
}

/// lavapipe's loop budget per shader invocation (see [`ShadeProgram::loop_iterations`]).
pub const LAVAPIPE_LOOP_LIMIT: u64 = 65535;

fn flag(flags: &[(&str, bool)], name: &str) -> bool {
    flags.iter().any(|&(n, on)| n == name && on)
}

/// A WGSL float literal that round-trips the f32 value.
fn wgsl_float(value: f64) -> String {
    let v = value as f32;
    let text = format!("{v:?}");
    if text.contains(['.', 'e']) {
        text
    } else {
        format!("{text}.0")
    }
}

/// The generic program's loop bounds: the order, coefficient count and node count read
/// from the uniforms instead of the constants (array sizes use the `_CAP` constants).
fn runtime_bounds(source: &str) -> String {
    let mut out = String::with_capacity(source.len());
    let mut word = String::new();
    let flush = |word: &mut String, out: &mut String| {
        out.push_str(match word.as_str() {
            "ORDER" => "params.order",
            "COUNT" => "params.coefficient_count",
            "QUAD_ROWS" => "params.quad_rows",
            "QUAD_AZIMUTHS" => "params.quad_azimuths",
            other => other,
        });
        word.clear();
    };
    for c in source.chars() {
        if c.is_ascii_alphanumeric() || c == '_' {
            word.push(c);
        } else {
            flush(&mut word, &mut out);
            out.push(c);
        }
    }
    flush(&mut word, &mut out);
    out
}

/// A `//#if` naming a feature the program does not know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: //#if {name}: unknown feature (known: {known})")]
pub struct UnknownFeature {
    pub line: usize,
    pub name: String,
    pub known: String,
}

/// Keeps the lines of `source` whose enclosing `//#if FEATURE` / `//#if !FEATURE` /
/// `//#else` / `//#endif` blocks are active for `flags`; a feature `flags` does not name
/// is an error, never silently off.
pub fn preprocess(source: &str, flags: &[(&str, bool)]) -> Result<String, UnknownFeature> {
    let mut out = String::with_capacity(source.len());
    let mut stack: Vec<(bool, bool)> = Vec::new(); // (this block's condition, parent active)
    let active = |stack: &[(bool, bool)]| stack.last().is_none_or(|&(condition, parent)| condition && parent);
    for (number, line) in source.lines().enumerate() {
        let directive = line.trim_start();
        if let Some(name) = directive.strip_prefix("//#if ") {
            let name = name.trim();
            let (negated, name) = match name.strip_prefix('!') {
                Some(rest) => (true, rest),
                None => (false, name),
            };
            let Some(&(_, on)) = flags.iter().find(|(n, _)| *n == name) else {
                let known = flags.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ");
                return Err(UnknownFeature { line: number + 1, name: name.to_string(), known });
            };
            let parent = active(&stack);
            stack.push((on != negated, parent));
        } else if directive.starts_with("//#else") {
            if let Some(top) = stack.last_mut() {
                top.0 = !top.0;
            }
        } else if directive.starts_with("//#endif") {
            stack.pop();
        } else if active(&stack) {
            out += line;
            out.push('\n');
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preprocess_keeps_active_blocks_only() {
        let source = "a\n//#if X\nb\n//#if Y\nc\n//#else\nd\n//#endif\n//#else\ne\n//#endif\nf\n";
        assert_eq!(preprocess(source, &[("X", true), ("Y", false)]).unwrap(), "a\nb\nd\nf\n");
        assert_eq!(preprocess(source, &[("X", false), ("Y", true)]).unwrap(), "a\ne\nf\n");
        assert_eq!(preprocess(source, &[("X", true), ("Y", true)]).unwrap(), "a\nb\nc\nf\n");
    }

    #[test]
    fn preprocess_refuses_an_unknown_feature() {
        let error = preprocess("a\n//#if X\nb\n//#if !TYPO\nc\n//#endif\n//#endif\n", &[("X", true)]).unwrap_err();
        assert_eq!((error.line, error.name.as_str()), (4, "TYPO"));
    }

    #[test]
    fn every_shader_tests_known_features_only() {
        let flags: Vec<(&str, bool)> = FLAG_NAMES.iter().map(|&n| (n, true)).collect();
        for (name, source) in [
            ("sh.wgsl", SH_WGSL),
            ("logsh.wgsl", LOGSH_WGSL),
            ("heightfield.wgsl", HEIGHTFIELD_WGSL),
            ("exp_quad.wgsl", EXP_QUAD_WGSL),
            ("exp_ol.wgsl", EXP_OL_WGSL),
            ("exp_product.wgsl", EXP_PRODUCT_WGSL),
            ("disk.wgsl", DISK_WGSL),
            ("shade.wgsl", SHADE_WGSL),
            ("pyramid.wgsl", PYRAMID_WGSL),
        ] {
            if let Err(e) = preprocess(source, &flags) {
                panic!("shaders/{name}: {e}");
            }
        }
    }

    #[test]
    fn generic_bounds_replace_whole_words_only() {
        assert_eq!(
            runtime_bounds("for (i < COUNT) { a[ORDER_CAP] = T_ORDER + ORDER + QUAD_ROWS; }"),
            "for (i < params.coefficient_count) { a[ORDER_CAP] = T_ORDER + params.order + params.quad_rows; }"
        );
    }

    #[test]
    fn float_literals_round_trip() {
        for v in [0.0, 1.0, Y0, ONE_DC, 1e-9, 16.0] {
            let text = wgsl_float(v);
            assert_eq!(text.parse::<f32>().unwrap(), v as f32, "{text}");
        }
    }
}
