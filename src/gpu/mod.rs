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

pub use executor::{Gpu, Stage, StageTimings};

use crate::shade::ShadeError;

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
    #[error("GPU error on {adapter} during {during}: {message}")]
    Wgpu { adapter: String, during: String, message: String },
    #[error(transparent)]
    Shade(#[from] ShadeError),
}
