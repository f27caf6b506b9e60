//! logsh: log-SH shading of Blender G-buffers.
pub mod logsh;
pub mod sh;
