//! Per-pixel shading on the CPU: the oracle the GPU pass is compared with and the
//! fallback on machines without a GPU adapter.
pub mod frame;
pub mod kernel;
pub mod passes;
pub mod settings;

pub use frame::{pixel_work, shade_frame, shade_frame_timed, PixelWork, ShadeError, ShadedFrame};
pub use kernel::PixelPasses;
pub use kernel::{Exponentiator, Occluders, ShadingKernel, SurfacePoint};
pub use passes::{shade_frame_passes, ShadedPasses};
pub use settings::{default_epsilon, Quality, ShadingSettings};
