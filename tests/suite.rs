//! logsh's test suite, as one binary: each module is a file of this directory, its doc
//! comment says what it checks. One binary links wgpu and the crate once, where a binary
//! per file linked them seventeen times.
//!
//!     cargo test                          # everything
//!     cargo test --test suite gpu::       # one module
//!     cargo test --test suite -- --nocapture reference::   # with its printed figures

#[macro_use]
mod support;

mod blender;
mod cli;
mod docs;
mod extremes;
mod gpu;
mod heightfield;
mod layers;
mod logsh_blocks;
mod point_lamps;
mod reference;
mod relight;
mod render_cli;
mod scene_format;
mod sh_math;
mod shading;
mod suns;
mod supersample;
mod synth;
mod view;
