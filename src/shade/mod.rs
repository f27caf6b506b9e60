//! The per-pixel pipeline, in the order a frame meets it: [`plan`] prepares a frame once
//! for either executor (settings, checks, height field, pyramid plan, light, kernel
//! tables, the blockers' [`blocker_tree`], each cap's fitted [`fitted_depth`]); [`frame`] says what each pixel is; [`kernel`] shades one surface point (the
//! math both executors share; [`sun`] its sharp lights, [`sharp_lights`] the suns taken
//! out of an environment map; [`visibility_grid`] the occluders' visibility computed once
//! per block of pixels); [`cpu`] is the CPU executor (the GPU one is in
//! `src/gpu/`); [`compositing`] assembles the passes of `logsh render`.
pub mod adaptive;
pub mod blocker_tree;
pub mod bounce;
pub mod cap_detail;
pub mod cap_packet;
pub mod compositing;
pub mod cpu;
pub mod exponentiator;
pub mod fitted_depth;
pub mod frame;
pub mod glossy;
pub mod kernel;
pub mod plan;
pub mod point;
pub mod resolve;
pub mod settings;
pub mod shaded;
pub mod sharp_lights;
pub mod sun;
pub mod sun_shadow;
pub mod visibility_grid;

pub use compositing::ShadedPasses;
pub use frame::{pixel_source, pixel_work, work_of, PixelSource, PixelWork, ShadeError, ShadedFrame, Tint};
pub use kernel::{CapSums, Caps, Exponentiator, KnownAlongSun, Occluders, PixelPasses, ShadingKernel, SurfacePoint};
pub use plan::{frame_settings, FrameContents, FramePlan, PlannedKernel, Terrain};
pub use resolve::{PixelFilter, Resolve, Resolving};
pub use settings::{
    default_epsilon, GlossyMethod, LightWindow, MarchLevels, Precision, Quality, SettingsError, ShadingSettings,
};
pub use shaded::{Outputs, Shaded};
