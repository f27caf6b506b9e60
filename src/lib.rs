//! logsh: log-SH shading of Blender G-buffers.
pub mod sh;
