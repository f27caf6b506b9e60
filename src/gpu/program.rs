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

use super::layout::{wgsl_declarations, GpuMaterial, MATERIAL_DIFFUSE, MATERIAL_PHONG};
use crate::heightfield::{LevelReconstruction, PyramidPlan, ScaleMax};
use crate::scene::Material;
use crate::sh::basis::{coefficient_count, funk_hecke_factor, nlp_scale, normalisation};
use crate::sh::exp::{ol_node_count, OL_COARSE_STEP, OL_FINE_NODES, ONE_DC, SERIES_MAX_TERMS, Y0};
use crate::sh::ExpMethod;
use crate::shade::kernel::{sh_space_max_magnitude, LUMINANCE, SH_SPACE_BLEND};
use crate::shade::ShadingKernel;
use std::collections::BTreeMap;

const SH_WGSL: &str = include_str!("../../shaders/sh.wgsl");
const LOGSH_WGSL: &str = include_str!("../../shaders/logsh.wgsl");
const HEIGHTFIELD_WGSL: &str = include_str!("../../shaders/heightfield.wgsl");
const EXP_QUAD_WGSL: &str = include_str!("../../shaders/exp_quad.wgsl");
const EXP_OL_WGSL: &str = include_str!("../../shaders/exp_ol.wgsl");
const EXP_PRODUCT_WGSL: &str = include_str!("../../shaders/exp_product.wgsl");
const SHADE_WGSL: &str = include_str!("../../shaders/shade.wgsl");
/// The pyramid pre-pass (fixed source: it depends on no setting).
pub const PYRAMID_WGSL: &str = include_str!("../../shaders/pyramid.wgsl");

/// What a frame's shading pass contains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Features {
    pub heightfield: bool,
    pub blockers: bool,
    pub phong: bool,
    /// How far the program is specialised; less than [`Specialisation::Full`] only to
    /// measure what specialisation saves (`logsh bench --specialise`).
    pub specialisation: Specialisation,
    /// The visibility terms of `logsh render`'s compositing passes (three more diffuse
    /// exponentiations per point; src/shade/kernel/passes.rs).
    pub passes: bool,
}

impl Features {
    fn flags(&self, exp: ExpMethod) -> Vec<(&'static str, bool)> {
        let all = self.specialisation != Specialisation::Full;
        vec![
            ("HEIGHTFIELD", self.heightfield || all),
            ("BLOCKERS", self.blockers || all),
            ("PHONG", self.phong || all),
            ("EXP_QUAD", matches!(exp, ExpMethod::Quad | ExpMethod::Exact)),
            ("EXP_OL", exp == ExpMethod::Ol),
            ("EXP_HYB", exp == ExpMethod::Hyb),
            ("EXP_SERIES", exp == ExpMethod::Series),
            ("PASSES", self.passes),
        ]
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
    pub fn of(plan: &PyramidPlan, reconstruction: LevelReconstruction, scale_max: ScaleMax) -> Self {
        Self {
            directions: plan.directions.len(),
            levels: plan.steps.last().map_or(1, |s| s.level + 1),
            steps: plan.steps.len(),
            bspline_levels: reconstruction == LevelReconstruction::BicubicBSpline,
            bspline_scale_max: scale_max == ScaleMax::BSpline,
        }
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
    /// Quadrature nodes of the exponentiation.
    pub nodes: usize,
    order: usize,
    exp: ExpMethod,
    march: Option<MarchShape>,
    tensor_entries: usize,
}

impl ShadeProgram {
    /// Generates the program from the CPU kernel's tables. `march` is `Some` when the
    /// frame has a height field.
    pub fn new(kernel: &ShadingKernel<f32>, features: Features, march: Option<MarchShape>) -> Self {
        let order = kernel.order;
        let count = coefficient_count(order);
        let exp = kernel.exp.method;
        let mut t = TableBuilder::default();

        // The basis and rotation constants (src/sh/basis.rs).
        t.push(
            "T_SH_NORMALISATION",
            (0..order).flat_map(|l| {
                (-(l as i64)..=l as i64).map(move |m| {
                    let k = normalisation(l, m.unsigned_abs() as usize);
                    (if m == 0 { k } else { std::f64::consts::SQRT_2 * k }) as f32
                })
            }),
        );
        t.push(
            "T_DOUBLE_FACTORIAL",
            (0..order).map(|m| (1..=m).fold(1.0f64, |acc, k| acc * (2 * k - 1) as f64) as f32),
        );
        t.push("T_FUNK_HECKE", (0..order).map(|l| funk_hecke_factor(l) as f32));
        t.push("T_NLP_SCALE", (0..order).map(|l| nlp_scale(l) as f32));
        // 2 pi K_l of the cap's closed form (src/logsh/cap.rs).
        t.push(
            "T_CAP_SCALE",
            (0..order).map(|l| {
                (2.0 * std::f64::consts::PI * ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI)).sqrt()) as f32
            }),
        );

        // Lobes: order log-ZH values then the log of the peak.
        t.push("T_TANGENT", kernel.tangent.iter().copied());
        t.push("T_DIFFUSE", kernel.diffuse.zonal.iter().copied().chain([kernel.diffuse.log_peak as f32]));
        let mut materials = Vec::new();
        let mut slots = BTreeMap::new();
        for (&index, lobes) in &kernel.materials {
            let (albedo, specular, kind, phong_lobe) = match (&lobes.material, &lobes.phong) {
                (Material::Phong { albedo, specular, .. }, Some(lobe)) => {
                    let offset = t.push_unnamed(lobe.zonal.iter().copied().chain([lobe.log_peak as f32]));
                    (*albedo, *specular, MATERIAL_PHONG, offset as u32)
                }
                (Material::Diffuse { albedo } | Material::Heightfield { albedo }, _) => {
                    (*albedo, [0.0; 3], MATERIAL_DIFFUSE, 0)
                }
                // Water is never shaded itself: its pixels are the reflected points.
                _ => continue,
            };
            slots.insert(index, materials.len() as u32);
            materials.push(GpuMaterial {
                albedo: [albedo[0], albedo[1], albedo[2], 0.0],
                specular: [specular[0], specular[1], specular[2], 0.0],
                kind,
                phong_lobe,
                ..Default::default()
            });
        }
        if materials.is_empty() {
            materials.push(GpuMaterial::default());
        }

        // The light, channel-major, and the exponentiation's tables (src/sh/exp.rs).
        let light = &kernel.light;
        t.push("T_LIGHT", light.iter().flat_map(|channel| channel.iter().copied()));
        let quadrature = kernel.exp.exact.as_ref().expect("every exponentiator carries its quadrature");
        let nodes = quadrature.weights().len();
        t.push("T_QUAD_WEIGHTS", quadrature.weights().iter().map(|&w| w as f32));
        // Rows padded with zeros to a multiple of 4 (the shader reads them as vec4).
        let padded = count.div_ceil(4) * 4;
        t.push(
            "T_QUAD_BASIS",
            quadrature
                .basis()
                .chunks(count)
                .flat_map(|y| y.iter().map(|&v| v as f32).chain(std::iter::repeat_n(0.0, padded - count))),
        );
        // L(node) = sum_i L_i y_i(node), per channel.
        t.push(
            "T_NODE_LIGHT",
            quadrature.basis().chunks(count).flat_map(|y| {
                (0..3).map(move |c| y.iter().zip(&light[c]).map(|(a, &b)| a * f64::from(b)).sum::<f64>() as f32)
            }),
        );
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

        // The height field's wedge operator, z-rotation phases and azimuths
        // (src/logsh/wedge.rs, src/heightfield/pyramid.rs).
        let directions = march.map_or(0, |m| m.directions);
        match &kernel.wedge {
            Some(wedge) => {
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
            None => {
                for name in ["T_WEDGE", "T_PHASES", "T_AZIMUTHS"] {
                    t.push(name, []);
                }
            }
        }
        if t.data.is_empty() {
            t.data.push(0.0);
        }

        let march_in = march;
        let march = march.unwrap_or_default();
        let runtime_order = features.specialisation == Specialisation::None;
        let order_cap = if runtime_order { crate::sh::MAX_ORDER } else { order };
        // Coefficient arrays hold a multiple of 4 entries (the padding stays 0).
        let count_cap = (order_cap * order_cap).div_ceil(4) * 4;
        let mut prelude = format!(
            "const ORDER: u32 = {order}u;\nconst ORDER_CAP: u32 = {}u;\nconst ORDER_PLUS_ONE: u32 = {}u;\n\
             const COUNT: u32 = {count}u;\nconst COUNT_CAP: u32 = {}u;\n\
             const NODES: u32 = {nodes}u;\nconst DIRECTIONS: u32 = {}u;\nconst LEVELS: u32 = {}u;\n\
             const STEPS: u32 = {}u;\nconst STEP_ARRAY: u32 = {}u;\n\
             const BSPLINE_LEVELS: bool = {};\nconst BSPLINE_SCALE_MAX: bool = {};\n\
             const GENERIC: bool = {};\nconst TANGENT_OCCLUSION: bool = {};\nconst RATIO_ATTENUATION: bool = {};\n\
             const Y0: f32 = {};\nconst ONE_DC: f32 = {};\n\
             const OL_FINE_NODES: u32 = {OL_FINE_NODES}u;\nconst OL_COARSE_STEP: f32 = {};\nconst OL_NODES: u32 = {}u;\n\
             const HYB_MAX_SQUARINGS: u32 = {}u;\nconst SERIES_MAX_TERMS: u32 = {SERIES_MAX_TERMS}u;\n\
             const SERIES_TOLERANCE: f32 = {};\nconst SH_SPACE_MAX_MAGNITUDE: f32 = {};\n\
             const SH_SPACE_BLEND: f32 = {};\nconst LUMINANCE: vec3<f32> = vec3<f32>({}, {}, {});\n",
            order_cap,
            order_cap + 1,
            count_cap,
            directions.max(1),
            march.levels.max(1),
            march.steps,
            march.steps.max(1),
            march.bspline_levels,
            march.bspline_scale_max,
            features.specialisation != Specialisation::Full,
            kernel.tangent_occlusion,
            kernel.ratio_attenuation,
            wgsl_float(Y0),
            wgsl_float(ONE_DC),
            wgsl_float(OL_COARSE_STEP),
            ol_node_count(),
            crate::sh::exp::HYB_MAX_SQUARINGS,
            wgsl_float(f64::from(f32::EPSILON) * 0.01),
            wgsl_float(sh_space_max_magnitude(exp)),
            wgsl_float(SH_SPACE_BLEND),
            wgsl_float(LUMINANCE[0]),
            wgsl_float(LUMINANCE[1]),
            wgsl_float(LUMINANCE[2]),
        );
        for (name, offset) in &t.offsets {
            prelude += &format!("const {name}: u32 = {offset}u;\n");
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
        modules.push(SHADE_WGSL);
        let mut source = wgsl_declarations() + &prelude;
        for module in modules {
            let module = preprocess(module, &flags);
            source += &if runtime_order { runtime_bounds(&module) } else { module };
        }
        let tensor_entries = kernel.exp.tensor.as_ref().map_or(0, |t| t.entry_count());
        Self { source, features, tables: t.data, materials, slots, nodes, order, exp, march: march_in, tensor_entries }
    }
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
        let quad = self.nodes as u64 * (c.div_ceil(4) + 1);
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
        let sphere = 1 + 2 * n + add_rotated;
        let heightfield = self.march.map_or(0, |m| {
            let sample = if m.bspline_levels { 21 } else { 1 };
            let steps = m.steps as u64;
            let horizon = steps * (1 + sample) + if m.bspline_scale_max { steps } else { 0 };
            let wedge = c * (1 + n) + n * (n + 1) / 2 + c;
            m.levels as u64 * (1 + sample) + m.directions as u64 * (1 + horizon + 2 * n + wedge) + wedge
        });
        let passes = if self.features.passes { 2 * tangent + 3 * lit + n } else { 0 };
        1 + tangent + heightfield + spheres as u64 * sphere + 2 * lit + passes
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
            "NODES" => "params.nodes",
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

/// Keeps the lines of `source` whose enclosing `//#if FEATURE` / `//#if !FEATURE` /
/// `//#else` / `//#endif` blocks are active for `flags`; unknown features are off.
pub fn preprocess(source: &str, flags: &[(&str, bool)]) -> String {
    let mut out = String::with_capacity(source.len());
    let mut stack: Vec<(bool, bool)> = Vec::new(); // (this block's condition, parent active)
    let active = |stack: &[(bool, bool)]| stack.last().is_none_or(|&(condition, parent)| condition && parent);
    for line in source.lines() {
        let directive = line.trim_start();
        if let Some(name) = directive.strip_prefix("//#if ") {
            let name = name.trim();
            let (negated, name) = match name.strip_prefix('!') {
                Some(rest) => (true, rest),
                None => (false, name),
            };
            let parent = active(&stack);
            stack.push((flag(flags, name) != negated, parent));
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
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preprocess_keeps_active_blocks_only() {
        let source = "a\n//#if X\nb\n//#if Y\nc\n//#else\nd\n//#endif\n//#else\ne\n//#endif\nf\n";
        assert_eq!(preprocess(source, &[("X", true), ("Y", false)]), "a\nb\nd\nf\n");
        assert_eq!(preprocess(source, &[("X", false), ("Y", true)]), "a\ne\nf\n");
        assert_eq!(preprocess(source, &[("X", true), ("Y", true)]), "a\nb\nc\nf\n");
    }

    #[test]
    fn generic_bounds_replace_whole_words_only() {
        assert_eq!(
            runtime_bounds("for (i < COUNT) { a[ORDER_CAP] = T_ORDER + ORDER + NODES; }"),
            "for (i < params.coefficient_count) { a[ORDER_CAP] = T_ORDER + params.order + params.nodes; }"
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
