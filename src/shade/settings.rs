//! What a user chooses: order, clamp, exponentiation, attenuation and the height-field
//! march, with defaults chosen by measurement.

use crate::heightfield::HorizonSettings;
use crate::sh::{ExpMethod, MAX_ORDER, MIN_ORDER};

/// Most azimuthal directions W a kernel accepts (per-pixel buffers are on the stack).
pub const MAX_DIRECTIONS: usize = 64;

/// Smallest accepted eps. `log(1e-6) = -13.8` per clamped term keeps sums of thousands of
/// terms and their exponentials within f32's range.
pub const MIN_EPSILON: f64 = 1e-6;

/// The knobs of one shading run (recorded in a transfer frame's header).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ShadingSettings {
    /// SH order n: n^2 coefficients per log vector.
    pub order: usize,
    /// The log clamp eps (paper 000, Eq. 2 and 7) of the visibility terms and the diffuse
    /// lobe, relative to the lobe's peak.
    pub epsilon: f64,
    /// The clamp of Phong lobes; `None` takes, per exponent and order, the eps that
    /// minimises the L2 error between the SH lobe and the exponential of its log-SH lobe
    /// ([`crate::logsh::optimal_lobe_epsilon`], `docs/epsilon/`): sharp lobes need a far
    /// smaller eps than the visibility (order 4, r = 1024: 0.001, where the default 0.1
    /// gives an L2 error 65 times larger).
    pub phong_epsilon: Option<f64>,
    /// How `exp*` is computed.
    pub exp: ExpMethod,
    /// HYB's scaling threshold on `|f^|`.
    pub hyb_threshold: f64,
    /// Scale each sphere's log vector by `r / |c - p|` (paper 000, Section 4.2).
    pub ratio_attenuation: bool,
    /// Give each sphere's cap the log depth fitted for its angular radius, and each
    /// height-field slice's horizon band the one fitted for its width
    /// ([`super::fitted_depth`]), instead of `log(eps)`: small caps and low horizons no
    /// longer take more light than they block.
    pub fitted_depths: bool,
    /// Add the log visibility of the hemisphere behind each receiver's tangent plane:
    /// no light reaches an opaque surface from behind it, and leaving that hemisphere
    /// unclamped lets the band-limited lobe overshoot (an unoccluded plane comes out
    /// 1.20 instead of 1.03 at order 4, eps 0.1).
    pub tangent_occlusion: bool,
    /// Floor each quadrature node's log visibility at `log(eps)`, inside `exp*` (the
    /// `quad` and `exact` methods, and `quad`'s share of the others near their range's
    /// end): a direction behind several caps, or behind a cap and the tangent plane, is
    /// then clamped once, not once per cap (paper 000, Section 4.2's double counting).
    pub overlap_floor: bool,
    /// Sphere clusters whose bounding radius is at most this fraction of their distance
    /// are seen as one cap ([`super::blocker_tree`]); 0 sees every sphere.
    pub cluster_ratio: f64,
    /// Take the suns out of an environment map and shade them as sharp lights
    /// ([`super::sharp_lights`]); off keeps the whole map in SH.
    pub sharp_lights: bool,
    /// Take from the diffuse light the part of the map's detail beyond order n that each
    /// sphere's cap hides ([`super::cap_detail`]). Absent from a transfer frame, which is
    /// shaded without it.
    #[serde(default)]
    pub cap_detail: bool,
    /// The window on the light's SH bands ([`LightWindow`]).
    pub light_window: LightWindow,
    /// How glossy lobes are shaded ([`GlossyMethod`]).
    pub glossy: GlossyMethod,
    /// Height-field march: W, k, o.
    pub horizon: HorizonSettings,
    /// The march's k and o where sharp lights light a height field (`None`: those of
    /// [`Self::horizon`]); [`Self::for_frame`] puts them in. Absent from a transfer frame
    /// written before it existed, which was marched with `horizon`'s.
    #[serde(default)]
    pub lamp_levels: Option<MarchLevels>,
    /// The precision of the per-pixel kernel.
    pub precision: Precision,
    /// Bounce light ([`super::bounce`]); absent from a transfer frame written before it
    /// existed, which was shaded without.
    #[serde(default = "BounceSettings::none")]
    pub bounce: BounceSettings,
    /// Pixels per side of the blocks whose height-field horizons and log vector and whose
    /// sphere caps are computed once, at one pixel of each, and interpolated between the
    /// blocks ([`super::visibility_grid`]); 1 computes them at every pixel. Absent from a
    /// transfer frame written before it existed, which was shaded per pixel.
    #[serde(default = "one")]
    pub visibility_grid: usize,
}

/// The level step k and offset o of the height-field march (see [`HorizonSettings`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MarchLevels {
    pub level_step: f64,
    pub level_offset: f64,
}

/// The visibility grid of settings that predate it.
fn one() -> usize {
    1
}

/// Largest `visibility_grid` accepted.
pub const MAX_VISIBILITY_GRID: usize = 4;

/// How the glossy lobe of a `phong` material is shaded (`--glossy`). The first two read
/// a prefiltered environment scaled by a log-SH specular occlusion ([`super::glossy`]);
/// a light given as SH coefficients has no map to prefilter and is always shaded `sh`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GlossyMethod {
    /// The GGX lobe of the material's width, with GGX's directional albedo: the Glossy
    /// BSDF that `render_cycles.py` renders.
    Ggx,
    /// The Phong lobe of Eq. 27 (paper 000), cut by the tangent plane, prefiltered.
    Phong,
    /// The Phong lobe in log-SH (paper 000, Eq. 27): exact visibility weighting, but no
    /// sharper than the order resolves.
    Sh,
}

/// A window on the light's SH projection (`--light-window`), band `l` of order `n`
/// scaled by `w_l` (Sloan 2008, "Stupid Spherical Harmonics (SH) Tricks", Section 5): a
/// truncated projection rings around a bright region, and the window trades that ringing
/// for blur.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LightWindow {
    /// The projection as it is.
    None,
    /// Lanczos' sigma factors, `w_l = sinc(pi l / n)`.
    Lanczos,
    /// Hann, `w_l = (1 + cos(pi l / n)) / 2`.
    Hann,
}

impl LightWindow {
    /// `w_l` for band `l` of an order-`order` projection.
    pub fn weight(self, l: usize, order: usize) -> f64 {
        let x = std::f64::consts::PI * l as f64 / order as f64;
        match self {
            LightWindow::None => 1.0,
            LightWindow::Lanczos if l == 0 => 1.0,
            LightWindow::Lanczos => x.sin() / x,
            LightWindow::Hann => 0.5 * (1.0 + x.cos()),
        }
    }

    /// Scales each band of `coefficients` (an order-`order` projection) by its weight.
    pub fn apply(self, order: usize, coefficients: &mut [[f64; 3]]) {
        for l in 0..order {
            let w = self.weight(l, order);
            for c in &mut coefficients[l * l..(l + 1) * (l + 1)] {
                *c = c.map(|v| v * w);
            }
        }
    }
}

/// Precision of the per-pixel kernel (`--precision`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Single precision, as the GPU pass runs.
    F32,
    /// Double precision, on the CPU only: the oracle for rounding.
    F64,
}

/// A setting outside what the kernel accepts, named by its flag.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SettingsError {
    #[error("--order {0} is outside {MIN_ORDER}..={MAX_ORDER}")]
    Order(usize),
    #[error("--epsilon {0} must lie in [{MIN_EPSILON:e}, 1)")]
    Epsilon(f64),
    #[error("--phong-epsilon {0} must lie in [{MIN_EPSILON:e}, 1)")]
    PhongEpsilon(f64),
    #[error("HYB threshold {0} must be positive")]
    HybThreshold(f64),
    #[error("--directions {0} is outside 3..={MAX_DIRECTIONS}")]
    Directions(usize),
    #[error("--level-step {0} must be positive")]
    LevelStep(f64),
    #[error("--level-offset {0} must be zero or positive")]
    LevelOffset(f64),
    #[error("--cluster-ratio {0} is outside 0..={MAX_CLUSTER_RATIO}")]
    ClusterRatio(f64),
    #[error("--bounces {0} is outside 0..={MAX_BOUNCES}")]
    Bounces(usize),
    #[error("--bounce-grid {0} is outside {MIN_BOUNCE_GRID}..={MAX_BOUNCE_GRID}")]
    BounceGrid(usize),
    #[error("--bounce-stride {0} is outside 1..={MAX_BOUNCE_STRIDE}")]
    BounceStride(usize),
    #[error("--visibility-grid {0} is outside 1..={MAX_VISIBILITY_GRID}")]
    VisibilityGrid(usize),
    #[error("--visibility-grid {grid} interpolates visibility between neighbouring pixels, but {why}; {instead}")]
    VisibilityGridWithout { grid: usize, why: &'static str, instead: &'static str },
}

/// Default `cluster_ratio`: clusters spanning at most about 40 degrees are one cap. Against
/// seeing every sphere, it changes the mean pixel by 0.0006 (largest 0.02) on a scene of
/// 32 spheres and by 0.0015 (largest 0.01) with 10,000 particles added, which then cost
/// 3.4x the frame without them instead of 179x (`docs/method/blockers.md`).
pub const DEFAULT_CLUSTER_RATIO: f64 = 0.35;

/// Largest `cluster_ratio` accepted: beyond it a cluster spans more than 60 degrees.
pub const MAX_CLUSTER_RATIO: f64 = 0.5;

/// Default eps per order: the value minimising the mean absolute error on the
/// sphere-over-plane analytic scenes with the default exponentiation (`quad`, nodes clamped
/// at the lobe's peak) and tangent occlusion, every cap at `log(eps)`. With fitted cap
/// depths ([`super::fitted_depth`]) they stay near the best on eleven Blender scenes against
/// Cycles (mean 0.024 at order 4 against 0.026 at eps 0.07 and 0.023 at 0.13; 0.018 at
/// order 6 against 0.019 at 0.05 and 0.017 at 0.1), so they are kept. `cargo run --release --example
/// sphere_accuracy` prints the whole table (orders 3-8, eps 0.01-0.2, every method;
/// `-- --quick` for the defaults' method only); the minima:
///
/// | order | 3 | 4 | 5 | 6 | 7 | 8 |
/// | --- | --- | --- | --- | --- | --- | --- |
/// | eps | 0.15 | 0.1 | 0.07 | 0.07 | 0.07 | 0.07 |
/// | mean abs error | 0.021 | 0.017 | 0.025 | 0.011 | 0.008 | 0.007 |
pub fn default_epsilon(order: usize) -> f64 {
    match order {
        0..=3 => 0.15,
        4 => 0.1,
        _ => 0.07,
    }
}

impl ShadingSettings {
    /// Defaults at a given order.
    pub fn for_order(order: usize) -> Self {
        Self {
            order,
            epsilon: default_epsilon(order),
            phong_epsilon: None,
            exp: ExpMethod::Quad,
            hyb_threshold: crate::sh::exp::HYB_MAGNITUDE,
            ratio_attenuation: false,
            fitted_depths: true,
            tangent_occlusion: true,
            overlap_floor: true,
            cluster_ratio: DEFAULT_CLUSTER_RATIO,
            sharp_lights: true,
            cap_detail: true,
            light_window: LightWindow::None,
            glossy: GlossyMethod::Ggx,
            horizon: HorizonSettings::default(),
            lamp_levels: None,
            precision: Precision::F32,
            bounce: BounceSettings::DEFAULT,
            visibility_grid: 1,
        }
    }

    /// Checks the rules that span the whole settings.
    pub fn validate(&self) -> Result<(), SettingsError> {
        if !(MIN_ORDER..=MAX_ORDER).contains(&self.order) {
            return Err(SettingsError::Order(self.order));
        }
        if !(MIN_EPSILON..1.0).contains(&self.epsilon) {
            return Err(SettingsError::Epsilon(self.epsilon));
        }
        if let Some(e) = self.phong_epsilon {
            if !(MIN_EPSILON..1.0).contains(&e) {
                return Err(SettingsError::PhongEpsilon(e));
            }
        }
        if !(self.hyb_threshold > 0.0 && self.hyb_threshold.is_finite()) {
            return Err(SettingsError::HybThreshold(self.hyb_threshold));
        }
        if !(3..=MAX_DIRECTIONS).contains(&self.horizon.directions) {
            return Err(SettingsError::Directions(self.horizon.directions));
        }
        let environment = MarchLevels { level_step: self.horizon.level_step, level_offset: self.horizon.level_offset };
        for levels in std::iter::once(environment).chain(self.lamp_levels) {
            if !(levels.level_step > 0.0 && levels.level_step.is_finite()) {
                return Err(SettingsError::LevelStep(levels.level_step));
            }
            if !(levels.level_offset >= 0.0 && levels.level_offset.is_finite()) {
                return Err(SettingsError::LevelOffset(levels.level_offset));
            }
        }
        if !(0.0..=MAX_CLUSTER_RATIO).contains(&self.cluster_ratio) {
            return Err(SettingsError::ClusterRatio(self.cluster_ratio));
        }
        if self.bounce.bounces > MAX_BOUNCES {
            return Err(SettingsError::Bounces(self.bounce.bounces));
        }
        if !(MIN_BOUNCE_GRID..=MAX_BOUNCE_GRID).contains(&self.bounce.grid) {
            return Err(SettingsError::BounceGrid(self.bounce.grid));
        }
        if !(1..=MAX_BOUNCE_STRIDE).contains(&self.bounce.stride) {
            return Err(SettingsError::BounceStride(self.bounce.stride));
        }
        if !(1..=MAX_VISIBILITY_GRID).contains(&self.visibility_grid) {
            return Err(SettingsError::VisibilityGrid(self.visibility_grid));
        }
        Ok(())
    }

    /// The settings a frame is shaded with: where sharp lights (Sun or point lamps, or
    /// suns taken out of the map) light its height field (`sharp_lights_on_terrain`), the
    /// march takes [`Self::lamp_levels`]. A sharp light's shadow falls where its direction
    /// crosses the horizon, so the horizon's error moves the shadow's edge, where the
    /// environment's soft light averages it out.
    pub fn for_frame(&self, sharp_lights_on_terrain: bool) -> ShadingSettings {
        let mut settings = *self;
        if let Some(levels) = self.lamp_levels.filter(|_| sharp_lights_on_terrain) {
            settings.horizon.level_step = levels.level_step;
            settings.horizon.level_offset = levels.level_offset;
        }
        settings.lamp_levels = None;
        settings
    }
}

impl Default for ShadingSettings {
    fn default() -> Self {
        Quality::Default.settings()
    }
}

/// Named trade-offs between speed and accuracy. Every knob of a preset can still be set
/// on its own; the preset only supplies what is not given (`--quality`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Quality {
    /// Order 3, ol exponentiation (a table lookup), W 8, k 2, o 2: fastest.
    Draft,
    /// Order 4, quad, W 16, k 4, o 5 (k 6, o 6 under sharp lights).
    Default,
    /// Order 6, quad, W 24, k 4, o 5 (k 8, o 8 under sharp lights).
    High,
    /// Order 8, quad, W 32, k 8, o 4 (k 12, o 8 under sharp lights): most accurate.
    Ultra,
}

impl Quality {
    pub const ALL: [Quality; 4] = [Quality::Draft, Quality::Default, Quality::High, Quality::Ultra];

    pub fn name(self) -> &'static str {
        match self {
            Quality::Draft => "draft",
            Quality::Default => "default",
            Quality::High => "high",
            Quality::Ultra => "ultra",
        }
    }

    /// The preset's settings; eps is each order's default ([`default_epsilon`]).
    pub fn settings(self) -> ShadingSettings {
        let (order, exp, directions, level_step, level_offset) = match self {
            Quality::Draft => (3, ExpMethod::Ol, 8, 2.0, 2.0),
            // o 5 rather than the march's default 3: a low Sun lamp's shadow across a
            // canyon (`blender_scripts/scenes/canyon.py`) came out 0.0245 from Cycles'
            // direct light at o 3 and 0.0116 at o 5 (its far walls' crests were lowered
            // by the coarser levels), the Sun-lamp terrain and the dunes unchanged
            // (0.0108 / 0.0109, 0.0301 / 0.0302), at the same cost.
            Quality::Default => (4, ExpMethod::Quad, 16, 4.0, 5.0),
            Quality::High => (6, ExpMethod::Quad, 24, 4.0, 5.0),
            Quality::Ultra => (8, ExpMethod::Quad, 32, 8.0, 4.0),
        };
        // Under sharp lights, finer steps and levels: the canyon's low Sun lamp
        // (against Cycles' direct light, converted materials, 240x135) came out 0.0116
        // at k 4, o 5, 0.0103 at k 4, o 8, 0.0084 at k 8, o 5 and 0.0070 at k 6, o 6 (the
        // swell 0.0029 and 0.0021), at high 0.0098 and 0.0051 at k 8, o 8, and at ultra
        // 0.0130 and 0.0053 at k 12, o 8; the Sun-lamp terrain and the lantern were
        // unchanged; the canyon under a sun in its map in place of the lamp, 0.0136 and
        // 0.0096 at k 6, o 6. Environment light alone gains nothing from them (the dunes'
        // sky, 0.0234 and 0.0236 at k 6, o 6), and they add a quarter to a third to the
        // shading stage.
        let lamp_levels = match self {
            Quality::Draft => None,
            Quality::Default => Some((6.0, 6.0)),
            Quality::High => Some((8.0, 8.0)),
            Quality::Ultra => Some((12.0, 8.0)),
        };
        let mut settings = ShadingSettings::for_order(order);
        // The caps' hidden detail costs blocker scenes 1.3 to 1.7 times the CPU's shading
        // stage (docs/method/materials.md): the fastest preset goes without it.
        settings.cap_detail = self != Quality::Draft;
        settings.exp = exp;
        settings.horizon.directions = directions;
        settings.horizon.level_step = level_step;
        settings.horizon.level_offset = level_offset;
        settings.lamp_levels = lamp_levels.map(|(level_step, level_offset)| MarchLevels { level_step, level_offset });
        settings
    }
}

/// Most bounces `--bounces` accepts.
pub const MAX_BOUNCES: usize = 3;
/// Fewest and most texels per side of the terrain's grid (`--bounce-grid`).
pub const MIN_BOUNCE_GRID: usize = 8;
pub const MAX_BOUNCE_GRID: usize = 512;
/// Most pixels between gathers (`--bounce-stride`).
pub const MAX_BOUNCE_STRIDE: usize = 16;

/// How bounce light is computed (`--bounces`, `--bounce-grid`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BounceSettings {
    /// 0 (direct light only) to [`MAX_BOUNCES`].
    pub bounces: usize,
    /// Texels per side of the grid the terrain's radiance is shaded on.
    pub grid: usize,
    /// Pixels between the points where bounce light is gathered, along each axis
    /// ([`super::bounce::Surroundings::indirect`]).
    #[serde(default = "BounceSettings::default_stride")]
    pub stride: usize,
}

impl BounceSettings {
    /// The presets' bounce (chosen by measurement: docs/method/bounce-light.md).
    pub const DEFAULT: Self = Self { bounces: 2, grid: 64, stride: 8 };

    fn default_stride() -> usize {
        Self::DEFAULT.stride
    }

    /// No bounce.
    pub fn none() -> Self {
        Self { bounces: 0, ..Self::DEFAULT }
    }
}
