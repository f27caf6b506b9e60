//! The GPU executor: the per-pixel pipeline of [`crate::shade`] as one wgpu compute pass
//! over the frame (tiled where the frame exceeds the adapter's buffer limits), after a
//! pre-pass that builds the height-field pyramid on the GPU.
//!
//! - [`layout`]: the structs shared with WGSL, declared once.
//! - [`program`]: the WGSL composed for what the scene contains, and the tables it
//!   reads, generated from the CPU kernel (`shaders/` holds the modules).
//! - [`Gpu`]: adapter, device, pipeline cache, dispatch and timing.
//!
//! The CPU path is the oracle: `tests/gpu.rs` compares the two on lavapipe (Mesa's Vulkan
//! implementation on the CPU) in CI, within 0.002 per pixel for an unoccluded value of 1.

mod executor;
pub mod layout;
pub mod program;

pub use executor::Gpu;
pub use program::Specialisation;

use crate::scene::{Frame, Scene};
use crate::shade::{ShadeError, ShadedFrame, ShadedPasses, ShadingSettings};
use crate::timing::StageTimings;

/// Where shading runs (`--device`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceChoice {
    /// A GPU adapter if there is one (a software one such as lavapipe counts), the CPU
    /// path otherwise.
    Auto,
    /// A GPU adapter, or an error.
    Gpu,
    /// The CPU path.
    Cpu,
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (wgpu looked for {backends}). Install a Vulkan driver (on Debian and Ubuntu, \
         `apt-get install mesa-vulkan-drivers` provides lavapipe, which runs on the CPU), or shade with --device cpu"
    )]
    NoAdapter { backends: String },
    #[error("GPU adapter {adapter} refused a device: {message}")]
    NoDevice { adapter: String, message: String },
    #[error("the GPU path does not support {0}; use --device cpu")]
    Unsupported(String),
    #[error("{what} needs {needed} bytes of GPU buffer, more than adapter {adapter} allows ({limit} bytes)")]
    TooLarge { what: String, needed: u64, limit: u64, adapter: String },
    #[error(
        "{adapter} (lavapipe, Mesa's CPU Vulkan driver) ends each shader invocation after {limit} loop iterations, \
         and this frame needs up to {needed} per pixel ({what}): its image would be wrong. Shade with --device cpu, \
         or lower --order, --directions or the blocker count, or use a hardware GPU"
    )]
    LoopBudget { adapter: String, needed: u64, limit: u64, what: String },
    #[error("GPU error on {adapter} during {during}: {message}")]
    Wgpu { adapter: String, during: String, message: String },
    #[error(transparent)]
    Shade(#[from] ShadeError),
}

fn cpu_description() -> String {
    format!("cpu ({} threads)", rayon::current_num_threads())
}

/// The executor `--device` chose.
pub enum Executor {
    Cpu,
    /// `fallback`: chosen by `--device auto`, so a frame the adapter cannot shade
    /// correctly goes to the CPU path instead of failing.
    Gpu {
        gpu: Gpu,
        fallback: bool,
    },
}

impl Executor {
    /// Resolves `--device`. `auto` falls back to the CPU path, saying why on stderr in one
    /// line, when no adapter exists or the settings need f64; `gpu` fails instead.
    pub fn select(choice: DeviceChoice, settings: &ShadingSettings) -> Result<Self, GpuError> {
        match choice {
            DeviceChoice::Cpu => Ok(Self::Cpu),
            DeviceChoice::Gpu => {
                if settings.double_precision {
                    return Err(GpuError::Unsupported("--precision f64 (the GPU pass runs in f32)".into()));
                }
                Ok(Self::Gpu { gpu: Gpu::new()?, fallback: false })
            }
            DeviceChoice::Auto if settings.double_precision => {
                eprintln!(
                    "--device auto: shading on the CPU, since the GPU pass runs in f32 and --precision f64 was asked"
                );
                Ok(Self::Cpu)
            }
            DeviceChoice::Auto => match Gpu::new() {
                Ok(gpu) => Ok(Self::Gpu { gpu, fallback: true }),
                Err(e) => {
                    eprintln!("--device auto: shading on the CPU: {e}");
                    Ok(Self::Cpu)
                }
            },
        }
    }

    /// "cpu (N threads)" or "gpu: adapter".
    pub fn describe(&self) -> String {
        match self {
            Self::Cpu => cpu_description(),
            Self::Gpu { gpu, .. } => format!("gpu: {}", gpu.adapter()),
        }
    }

    pub fn shade(&self, scene: &Scene, frame: &Frame, settings: &ShadingSettings) -> Result<ShadedFrame, GpuError> {
        Ok(self.shade_timed(scene, frame, settings, Specialisation::Full)?.0)
    }

    /// The frame's compositing passes and visibility terms (`logsh render`).
    pub fn shade_passes(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
    ) -> Result<ShadedPasses, GpuError> {
        match self {
            Self::Cpu => Ok(crate::shade::shade_frame_passes(scene, frame, settings)?),
            Self::Gpu { gpu, fallback } => match gpu.shade_frame_passes(scene, frame, settings) {
                Err(e @ GpuError::LoopBudget { .. }) if *fallback => {
                    eprintln!("--device auto: shading frame {} on the CPU: {e}", frame.number);
                    Ok(crate::shade::shade_frame_passes(scene, frame, settings)?)
                }
                other => other,
            },
        }
    }

    /// Shades and times each stage; `specialisation` only matters on the GPU (see
    /// [`Gpu::shade_frame_timed`]).
    pub fn shade_timed(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        specialisation: Specialisation,
    ) -> Result<(ShadedFrame, StageTimings), GpuError> {
        let on_cpu = || -> Result<(ShadedFrame, StageTimings), GpuError> {
            let (shaded, mut timings) = crate::shade::shade_frame_timed(scene, frame, settings)?;
            timings.device = cpu_description();
            Ok((shaded, timings))
        };
        match self {
            Self::Cpu => on_cpu(),
            Self::Gpu { gpu, fallback } => match gpu.shade_frame_timed(scene, frame, settings, specialisation) {
                Err(e @ GpuError::LoopBudget { .. }) if *fallback => {
                    eprintln!("--device auto: shading frame {} on the CPU: {e}", frame.number);
                    on_cpu()
                }
                Ok((shaded, mut timings)) => {
                    timings.device = self.describe();
                    Ok((shaded, timings))
                }
                Err(e) => Err(e),
            },
        }
    }
}
