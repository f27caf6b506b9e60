//! logsh: soft environment shadows and glossy reflections for Blender G-buffers, by
//! log-SH exponentiation (Giraud and Nowrouzezahrai, "Practical Shading of Height Fields
//! and Meshes using Spherical Harmonic Exponentiation"; paper 000 in `docs/design.md`).
//!
//! Layout: [`sh`] is the SH core (basis, rotation, products, exponentiation), [`logsh`]
//! the log-SH building blocks of the paper, [`heightfield`] the horizon march of SN08,
//! [`scene`] the format-v1 reader and output writers, [`shade`] the per-pixel pipeline
//! (the frame plan, the kernel and the CPU executor), [`gpu`] the same pipeline as one
//! wgpu compute pass, [`executor`] the choice between the two, [`render`] the sequence
//! driver of `logsh render`, [`bench`](mod@bench) `logsh bench`,
//! [`reference`](mod@reference) the ground truth, [`compare`] the measure against Cycles,
//! [`synth`] procedural scenes, [`info`]
//! the EXR listing of `logsh info`, [`cli`] and [`run`] the command line; [`memo`] holds
//! the tables a process builds once.
pub mod bench;
pub mod cli;
pub mod compare;
pub mod executor;
pub mod gpu;
pub mod gpu_layout;
pub mod heightfield;
pub mod info;
pub mod logsh;
pub mod memo;
pub mod plot;
pub mod reference;
pub mod render;
pub mod run;
pub mod scene;
pub mod sh;
pub mod shade;
pub mod sweep;
pub mod synth;
pub mod timing;
pub mod transfer;
pub mod vector;
pub mod view;
#[cfg(target_arch = "x86_64")]
mod x86;
