//! Every struct the host and the shaders share, declared once (the GPU executor reads it
//! as `gpu::layout`; the CPU's blocker tree keeps its nodes in the same record): `gpu_struct!` emits the
//! `#[repr(C)]` Rust struct and its WGSL declaration from the same field list, and the
//! tests check with naga's layouter that both sides agree on every offset and the size.
//!
//! Fields are 4-byte scalars and `vec4`s only, grouped so that `repr(C)` and WGSL's
//! uniform and storage layouts coincide without hidden padding.

/// A Rust field type and its WGSL spelling.
pub trait WgslType {
    const WGSL: &'static str;
}

impl WgslType for u32 {
    const WGSL: &'static str = "u32";
}
impl WgslType for f32 {
    const WGSL: &'static str = "f32";
}
impl WgslType for [f32; 4] {
    const WGSL: &'static str = "vec4<f32>";
}
impl WgslType for [u32; 4] {
    const WGSL: &'static str = "vec4<u32>";
}

/// A struct shared with WGSL.
pub trait GpuStruct: bytemuck::Pod {
    const NAME: &'static str;
    /// `(field name, WGSL type)` in declaration order.
    fn fields() -> Vec<(&'static str, &'static str)>;
    /// Each field's byte offset in the Rust struct, in declaration order.
    fn offsets() -> Vec<usize>;
    /// The WGSL declaration.
    fn wgsl() -> String {
        let fields: String = Self::fields().iter().map(|(name, ty)| format!("    {name}: {ty},\n")).collect();
        format!("struct {} {{\n{fields}}}\n", Self::NAME)
    }
}

/// A record kept in the shading pass's `tables` (an `array<f32>`, [`crate::gpu`]'s
/// program tables) rather than in a buffer of its own: the host pushes it as its
/// bytes ([`TableRecord::floats`]), the shader reads it with `load_NAME(offset)`,
/// generated from the same field list and the Rust offsets.
pub trait TableRecord: GpuStruct {
    /// The record as the `f32`s of the tables, a `u32` field by its bits.
    fn floats(&self) -> Vec<f32> {
        bytemuck::cast_slice(std::slice::from_ref(self)).to_vec()
    }

    /// `fn load_NAME(base: u32) -> NAME`, reading the record at `tables[base]`, and
    /// `const NAME_FLOATS`, its length in the tables.
    fn wgsl_loader() -> String {
        let at = |offset: usize, k: usize| format!("tables[base + {}u]", offset / 4 + k);
        let values: Vec<String> = Self::fields()
            .iter()
            .zip(Self::offsets())
            .map(|(&(_, ty), offset)| match ty {
                "f32" => at(offset, 0),
                "u32" => format!("bitcast<u32>({})", at(offset, 0)),
                "vec4<f32>" => format!("vec4<f32>({})", (0..4).map(|k| at(offset, k)).collect::<Vec<_>>().join(", ")),
                "vec4<u32>" => format!(
                    "bitcast<vec4<u32>>(vec4<f32>({}))",
                    (0..4).map(|k| at(offset, k)).collect::<Vec<_>>().join(", ")
                ),
                other => unreachable!("no WgslType spells {other}"),
            })
            .collect();
        let name = Self::NAME;
        let floats = std::mem::size_of::<Self>() / 4;
        format!(
            "const {name}_FLOATS: u32 = {floats}u;\nfn load_{name}(base: u32) -> {name} {{\n    return {name}({});\n}}\n",
            values.join(", ")
        )
    }
}

macro_rules! gpu_struct {
    ($(#[$meta:meta])* $name:ident { $($(#[$field_meta:meta])* $field:ident : $ty:ty),* $(,)? }) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name {
            $($(#[$field_meta])* pub $field: $ty),*
        }

        impl GpuStruct for $name {
            const NAME: &'static str = stringify!($name);
            fn fields() -> Vec<(&'static str, &'static str)> {
                vec![$((stringify!($field), <$ty as WgslType>::WGSL)),*]
            }
            fn offsets() -> Vec<usize> {
                vec![$(std::mem::offset_of!($name, $field)),*]
            }
        }
    };
}

gpu_struct! {
    /// Per-dispatch parameters of the shading pass (a uniform).
    ShadeParams {
        /// Shading points in this tile.
        point_count: u32,
        /// Nodes of the frame's blocker tree ([`crate::shade::blocker_tree`]).
        node_count: u32,
        /// `log(eps)` of the visibility terms (paper 000, Eq. 7).
        log_epsilon: f32,
        /// HYB's scaling threshold on `|f^|`.
        hyb_threshold: f32,
        /// Height-field rectangle: `min.x, min.y, max.x, max.y`.
        heightfield_rect: [f32; 4],
        /// What the frame contains, [`FEATURE_HEIGHTFIELD`] | [`FEATURE_BLOCKERS`] |
        /// [`FEATURE_PHONG`]: read only by the generic (unspecialised) program.
        feature_bits: u32,
        /// SH order, coefficient count, and the quadrature's rows and azimuths per row
        /// ([`crate::sh::SeparableQuadrature`]): read only by the generic program, whose
        /// loop bounds are not constants.
        order: u32,
        coefficient_count: u32,
        quad_rows: u32,
        /// [`crate::shade::ShadingSettings::cluster_ratio`].
        cluster_ratio: f32,
        quad_azimuths: u32,
        /// The height field's highest sample: no level of the pyramid (tent-filtered,
        /// nonnegative weights) and no read of one rises above it.
        heightfield_peak: f32,
        /// The pixel of the tile's first point: point `i` is pixel `tile_start + i`.
        tile_start: u32,
        /// The G-buffer's width in pixels.
        image_width: u32,
        /// The visibility grid's blocks along x and y ([`crate::shade::visibility_grid`]).
        grid_columns: u32,
        grid_rows: u32,
        pad: u32,
    }
}

gpu_struct! {
    /// One point of a tile to shade, as the frame walk packs it.
    GpuPoint {
        /// World position (xyz) and the material slot's bits (w): a slot of the material
        /// table, [`SLOT_NONE`] or [`SLOT_UNKNOWN`].
        position_slot: [f32; 4],
        /// Unit normal (xyz) and the bits of the object index (w).
        normal: [f32; 4],
        /// The view direction mirrored about the normal (xyz): the Phong lobe's axis; 1
        /// (w) where the visibility grid serves the point (a surface seen directly,
        /// [`crate::shade::visibility_grid::is_direct_surface`]), else 0.
        reflected: [f32; 4],
    }
}

gpu_struct! {
    /// One shaded point, as the pass writes it back.
    GpuShaded {
        /// Diffuse radiance (rgb).
        diffuse: [f32; 4],
        /// Phong radiance (rgb).
        specular: [f32; 4],
        /// With the visibility terms compiled in: combined, height field, blockers (xyz);
        /// 1 otherwise.
        visibility: [f32; 4],
    }
}

gpu_struct! {
    /// One node of the blocker tree ([`crate::shade::blocker_tree::BlockerNode`]).
    GpuBlockerNode {
        /// Bounding sphere: centre (xyz) and radius (w).
        bounds: [f32; 4],
        /// The subtree seen as one sphere (a leaf's own sphere).
        equivalent: [f32; 4],
        /// The node after this subtree.
        skip: u32,
        /// 1 for a leaf.
        leaf: u32,
        /// Object index of the equivalent sphere (0: none).
        object: u32,
        /// The share of the equivalent sphere's solid angle that is its own
        /// ([`crate::shade::blocker_tree::overlap_shares`]).
        share: f32,
    }
}

gpu_struct! {
    /// One material slot: what the shading pass needs of a [`crate::scene::Material`].
    GpuMaterial {
        /// Diffuse albedo (rgb).
        albedo: [f32; 4],
        /// Phong specular colour (rgb); zero for diffuse materials.
        specular: [f32; 4],
        /// [`MATERIAL_DIFFUSE`] or [`MATERIAL_PHONG`].
        kind: u32,
        /// Offset of the Phong lobe's log-ZH in the tables (`order` values, then the log
        /// of its peak).
        phong_lobe: u32,
        /// Offset of the prefiltered map the glossy term reads (its width and height as
        /// u32 bits, then RGB texels row by row; src/shade/glossy.rs), or [`NO_MAP`] for
        /// the glossy term in log-SH.
        sharp_map: u32,
        /// Offset of the lobe's albedo table (`ALBEDO_ENTRIES` values), then of its open
        /// `exp*(lobe)` as ZH (`order` values).
        sharp_tables: u32,
    }
}

gpu_struct! {
    /// One pyramid level inside the levels buffer.
    GpuLevel {
        /// First sample of the level.
        offset: u32,
        columns: u32,
        rows: u32,
        pad: u32,
    }
}

gpu_struct! {
    /// One step of the horizon march ([`crate::heightfield::MarchStep`]).
    GpuStep {
        distance: f32,
        inv_distance: f32,
        level: u32,
        pad: u32,
    }
}

gpu_struct! {
    /// One decimated level of the pyramid pre-pass: where its tent taps and its
    /// samples live.
    GpuDecimation {
        /// Level-0 size.
        in_columns: u32,
        in_rows: u32,
        /// This level's size.
        out_columns: u32,
        out_rows: u32,
        /// First tap range along x (one per output column) and along y (one per row).
        ranges_x: u32,
        ranges_y: u32,
        /// Where pass x writes `in_rows x out_columns` values in the scratch buffer.
        scratch_offset: u32,
        /// Where pass y writes the level in the levels buffer.
        level_offset: u32,
    }
}

gpu_struct! {
    /// One tent tap: level-0 sample index along the axis, and weight.
    GpuTap {
        index: u32,
        weight: f32,
    }
}

gpu_struct! {
    /// A sun of the shading pass's tables (src/shade/sun.rs, [`TableRecord`]).
    GpuSun {
        /// Direction (xyz) and 1 - cos of the disk's half-angle (w).
        axis: [f32; 4],
        /// The disk integral, radiance times solid angle (rgb), and the patch radius of
        /// its directions (w).
        integral: [f32; 4],
        /// Offset of the sun's shadow map in the tables ([`GpuShadowMap`]), or
        /// [`NO_MAP`]: the blocker spheres shadow it then.
        shadow_map: u32,
        /// How far the disk's rays drift sideways per unit of depth in its map: the tangent
        /// of the disk's half-angle plus the map's tolerance (src/shade/sun_shadow.rs).
        drift: f32,
        pad: u32,
        pad_2: u32,
    }
}

gpu_struct! {
    /// A sun's shadow map of the blocker meshes in the shading pass's tables
    /// (src/shade/sun_shadow.rs, ShadowMapMarch; [`TableRecord`]), followed by its
    /// `levels` [`GpuLevel`]s of minima of `Z` (level 0 `Z` itself), whose `offset`s index
    /// the tables.
    GpuShadowMap {
        /// Unit, towards the sun (xyz), and the side of a texel in metres (w).
        axis: [f32; 4],
        /// The centre of the map's plane (xyz), and the shallowest depth in it (w).
        origin: [f32; 4],
        /// Unit, along the columns (xyz), and the width spanned (w).
        right: [f32; 4],
        /// Unit, up the rows (xyz), and the height spanned (w).
        up: [f32; 4],
        columns: u32,
        rows: u32,
        levels: u32,
        /// Offset of `Zfar` in the tables, level 0's layout.
        far: u32,
    }
}

gpu_struct! {
    /// A point lamp of the shading pass's tables (src/scene/light.rs, PointLight;
    /// [`TableRecord`]).
    GpuPointLamp {
        /// Position (xyz) and radius (w).
        position: [f32; 4],
        /// Power times colour over 4 pi (rgb), and 1 for Soft Falloff (w).
        intensity: [f32; 4],
    }
}

gpu_struct! {
    /// The head of a glossy lobe's tables (src/shade/glossy.rs, [`TableRecord`]), before
    /// its cone weights, albedo table, sharp lights' scale table and open lobe's ZH where
    /// it is prefiltered.
    GpuLobeHead {
        /// `LOBE_GGX`, `LOBE_PHONG` or `LOBE_SH`.
        kind: u32,
        /// GGX alpha or the Phong exponent.
        width: f32,
        /// 1 - cos of the lobe core's angular radius.
        core_one_minus_cos: f32,
        /// The patch radius of the core's directions.
        core_patch: f32,
        /// The cone test's share of the occlusion (the log-SH ratio has the rest).
        cone_share: f32,
        /// The reflectance at normal incidence of the sharp lights' Fresnel term.
        lamp_fresnel: f32,
    }
}

impl TableRecord for GpuSun {}
impl TableRecord for GpuShadowMap {}
impl TableRecord for GpuLevel {}
impl TableRecord for GpuPointLamp {}
impl TableRecord for GpuLobeHead {}

/// What the WGSL declarations and the layout test read of one shared struct.
pub struct Declared {
    pub name: &'static str,
    pub wgsl: String,
    /// Byte offsets of the fields in the Rust struct.
    pub offsets: Vec<usize>,
    pub size: usize,
}

fn declared<T: GpuStruct>() -> Declared {
    Declared { name: T::NAME, wgsl: T::wgsl(), offsets: T::offsets(), size: std::mem::size_of::<T>() }
}

/// Every struct the host and the shaders share: the one list the declarations and the
/// layout test read.
pub fn shared_structs() -> Vec<Declared> {
    vec![
        declared::<ShadeParams>(),
        declared::<GpuPoint>(),
        declared::<GpuShaded>(),
        declared::<GpuBlockerNode>(),
        declared::<GpuMaterial>(),
        declared::<GpuLevel>(),
        declared::<GpuStep>(),
        declared::<GpuDecimation>(),
        declared::<GpuTap>(),
        declared::<GpuSun>(),
        declared::<GpuShadowMap>(),
        declared::<GpuPointLamp>(),
        declared::<GpuLobeHead>(),
    ]
}

/// The loaders of the records of the shading pass's tables ([`TableRecord`]).
pub fn wgsl_table_loaders() -> String {
    [
        GpuSun::wgsl_loader(),
        GpuShadowMap::wgsl_loader(),
        GpuLevel::wgsl_loader(),
        GpuPointLamp::wgsl_loader(),
        GpuLobeHead::wgsl_loader(),
    ]
    .concat()
}

/// Invocations per workgroup of every compute pass (`@workgroup_size(WORKGROUP_SIZE)`).
pub const WORKGROUP_SIZE: u32 = 64;

/// [`ShadeParams::feature_bits`].
pub const FEATURE_HEIGHTFIELD: u32 = 1;
pub const FEATURE_BLOCKERS: u32 = 2;
pub const FEATURE_PHONG: u32 = 4;

/// [`GpuMaterial::kind`] values.
pub const MATERIAL_DIFFUSE: u32 = 0;
pub const MATERIAL_PHONG: u32 = 1;
/// [`GpuMaterial::sharp_map`] of a material without a prefiltered glossy term.
pub const NO_MAP: u32 = u32::MAX;
/// A point's material slot when nothing is shaded there (background, or a water pixel
/// whose mirror ray leaves the scene): the pass writes zero.
pub const SLOT_NONE: u32 = u32::MAX;
/// A point's slot when its material index is not in the scene's table: shaded black, as
/// the CPU path does.
pub const SLOT_UNKNOWN: u32 = u32::MAX - 1;

/// WGSL declarations of every shared struct and constant, prepended to each shader.
pub fn wgsl_declarations() -> String {
    let mut out: String = shared_structs().into_iter().map(|declared| declared.wgsl).collect();
    out += &format!("const WORKGROUP_SIZE: u32 = {WORKGROUP_SIZE}u;\n");
    out += &format!(
        "const FEATURE_HEIGHTFIELD: u32 = {FEATURE_HEIGHTFIELD}u;\nconst FEATURE_BLOCKERS: u32 = {FEATURE_BLOCKERS}u;\n\
         const FEATURE_PHONG: u32 = {FEATURE_PHONG}u;\nconst NO_MAP: u32 = {NO_MAP}u;\n"
    );
    out += &format!(
        "const MATERIAL_DIFFUSE: u32 = {MATERIAL_DIFFUSE}u;\nconst MATERIAL_PHONG: u32 = {MATERIAL_PHONG}u;\n\
         const SLOT_NONE: u32 = {SLOT_NONE}u;\nconst SLOT_UNKNOWN: u32 = {SLOT_UNKNOWN}u;\n"
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::naga;

    /// Offsets and size of struct `name` as naga lays it out in a uniform / storage
    /// buffer.
    fn naga_layout(name: &str) -> (Vec<u32>, u32) {
        let source = wgsl_declarations();
        let module = naga::front::wgsl::parse_str(&source).expect("declarations parse");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect("declared");
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{name} is not a struct") };
        let _ = handle;
        (members.iter().map(|m| m.offset).collect(), *span)
    }

    #[test]
    fn shared_structs_have_the_same_layout_on_both_sides() {
        for declared in shared_structs() {
            let (offsets, span) = naga_layout(declared.name);
            assert_eq!(span as usize, declared.size, "{}: WGSL size vs Rust size", declared.name);
            let offsets: Vec<usize> = offsets.into_iter().map(|o| o as usize).collect();
            assert_eq!(offsets, declared.offsets, "{}: WGSL offsets vs Rust offsets", declared.name);
        }
    }

    #[test]
    fn table_record_loaders_are_valid_wgsl() {
        let tables = "@group(0) @binding(1) var<storage, read> tables: array<f32>;\n";
        let source = wgsl_declarations() + tables + &wgsl_table_loaders();
        let module = naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{}", e.emit_to_string(&source)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .expect("the loaders validate");
    }

    #[test]
    fn uniform_structs_are_a_multiple_of_16_bytes() {
        assert_eq!(std::mem::size_of::<ShadeParams>() % 16, 0);
    }
}
