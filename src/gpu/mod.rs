//! The GPU executor: the per-pixel pipeline of [`crate::shade`] as one wgpu compute pass
//! over the frame (tiled where the frame exceeds the adapter's buffer limits), after a
//! pre-pass that builds the height-field pyramid on the GPU and, with a visibility grid
//! ([`crate::shade::visibility_grid`]), one that computes each block's horizons and caps.
//!
//! - [`layout`]: the structs shared with WGSL, declared once.
//! - [`program`]: the WGSL composed for what the scene contains, and the tables it
//!   reads, generated from the CPU kernel (`shaders/` holds the modules).
//! - `device`: [`Gpu`], the adapter and device, buffers, the pipeline cache, timing. A
//!   `Gpu` shared between threads shades one frame at a time.
//! - `frame`: one frame's shading pass (prepare, bind with the grid's pre-pass, pack a
//!   tile, run a tile), from the same [`crate::shade::FramePlan`] as the CPU executor.
//! - `pyramid`: the height-field pyramid pre-pass.
//!
//! Which executor shades a frame is chosen above this module, in `src/executor.rs`.
//!
//! The CPU path is the oracle: `tests/gpu.rs` compares the two on lavapipe (Mesa's Vulkan
//! implementation on the CPU) in CI, within 0.002 per pixel for an unoccluded value of 1.

mod device;
mod frame;
pub use crate::gpu_layout as layout;
pub mod program;
mod pyramid;

pub use device::Gpu;
pub use program::Specialisation;

use crate::shade::ShadeError;

impl GpuError {
    /// The GPU pass runs in f32 only.
    pub fn double_precision() -> Self {
        Self::Unsupported("--precision f64 (the GPU pass runs in f32)".into())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (wgpu looked for {backends}). Install a Vulkan driver (on Debian and Ubuntu, \
         `apt-get install mesa-vulkan-drivers` provides lavapipe, which runs on the CPU), or shade with --device cpu"
    )]
    NoAdapter { backends: String },
    #[error(
        "the only GPU adapter found is a software driver running on the CPU, more slowly than logsh's CPU \
         executor ({adapters}); --device gpu uses it anyway"
    )]
    SoftwareOnly { adapters: String },
    #[error("GPU adapter {adapter} refused a device: {message}")]
    NoDevice { adapter: String, message: String },
    #[error("the GPU path does not support {0}; use --device cpu")]
    Unsupported(String),
    #[error("{what} needs {needed} bytes of GPU buffer, more than adapter {adapter} allows ({limit} bytes)")]
    TooLarge { what: String, needed: u64, limit: u64, adapter: String },
    #[error(
        "{adapter} (lavapipe, Mesa's CPU Vulkan driver) ends each shader invocation after {limit} loop iterations, \
         and this frame needs up to {needed} per pixel ({what}): its image would be wrong. Shade with --device cpu, \
         or lower --order, --directions, --level-step, --level-offset or the blocker count (under sharp lights the \
         presets march finer), or use a hardware GPU"
    )]
    LoopBudget { adapter: String, needed: u64, limit: u64, what: String },
    #[error("GPU error on {adapter} during {during}: {message}")]
    Wgpu { adapter: String, during: String, message: String },
    #[error(transparent)]
    Shade(#[from] ShadeError),
}
