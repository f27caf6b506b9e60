//! Command-line options: parsed by clap into these structs, then turned into settings in
//! a separate step that checks the rules spanning several flags.

use crate::heightfield::HorizonSettings;
use crate::shade::{default_epsilon, ShadingSettings};
use crate::sh::ExpMethod;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Parser, Debug)]
#[command(name = "logsh", version, about = "Soft environment shadows and glossy reflections for Blender G-buffers, by log-SH exponentiation")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Shade one frame of a scene directory (format v1) into a linear EXR and a PNG preview.
    Shade(ShadeArgs),
    /// Write a procedural sample scene in format v1 (the scenes in gbuffers/ come from here).
    Example(ExampleArgs),
}

#[derive(Args, Debug)]
pub struct ShadeArgs {
    /// Scene directory holding scene.json.
    pub scene: PathBuf,
    /// Frame to shade [default: the scene's first frame, or 1].
    #[arg(long)]
    pub frame: Option<i64>,
    /// Output directory; receives beauty.NNNN.exr (linear RGBA) and beauty.NNNN.png (sRGB).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    #[command(flatten)]
    pub shading: ShadingArgs,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum ExpArg {
    /// Quadrature on a coarse (2n+2)-node grid: within 1e-5 of exact.
    Quad,
    /// Scale until small, optimal linear, square back (the paper's choice); 2-4x faster than quad, less accurate.
    Hyb,
    /// Optimal linear only: fastest, least accurate at large magnitudes.
    Ol,
    /// DC isolation and the product series.
    Series,
    /// Quadrature on a fine grid: reference quality, slow.
    Exact,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum Switch {
    On,
    Off,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum PrecisionArg {
    F32,
    F64,
}

/// The shading knobs shared by every command that shades.
#[derive(Args, Debug, Clone)]
pub struct ShadingArgs {
    /// SH order n (n^2 coefficients), 3 to 8. Higher is sharper and slower.
    #[arg(long, default_value_t = 4)]
    pub order: usize,
    /// Log clamp eps, relative to each lobe's peak, in [1e-6, 1) [default per order, chosen by measurement: 0.15 at order 3, 0.1 at 4, 0.07 at 5-8].
    #[arg(long)]
    pub epsilon: Option<f64>,
    /// Height field: number of azimuthal directions W.
    #[arg(long, default_value_t = HorizonSettings::default().directions)]
    pub directions: usize,
    /// Height field: pyramid level step k (levels per halving of resolution).
    #[arg(long, default_value_t = HorizonSettings::default().level_step)]
    pub level_step: f64,
    /// Height field: pyramid level offset o.
    #[arg(long, default_value_t = HorizonSettings::default().level_offset)]
    pub level_offset: f64,
    /// SH exponentiation method.
    #[arg(long, value_enum, default_value_t = ExpArg::Quad)]
    pub exp: ExpArg,
    /// Scale each sphere's log visibility by r/|c-p| (the paper's Section 4.2).
    #[arg(long, value_enum, default_value_t = Switch::Off)]
    pub ratio_attenuation: Switch,
    /// Clamp the hemisphere behind each receiver's tangent plane in log space.
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub tangent_occlusion: Switch,
    /// Precision of the per-pixel kernel.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
}

impl ShadingArgs {
    /// The settings these flags describe, checked.
    pub fn settings(&self) -> Result<ShadingSettings, String> {
        let mut settings = ShadingSettings::for_order(self.order);
        settings.epsilon = self.epsilon.unwrap_or_else(|| default_epsilon(self.order));
        settings.exp = match self.exp {
            ExpArg::Hyb => ExpMethod::Hyb,
            ExpArg::Ol => ExpMethod::Ol,
            ExpArg::Series => ExpMethod::Series,
            ExpArg::Quad => ExpMethod::Quad,
            ExpArg::Exact => ExpMethod::Exact,
        };
        settings.ratio_attenuation = self.ratio_attenuation == Switch::On;
        settings.tangent_occlusion = self.tangent_occlusion == Switch::On;
        settings.horizon.directions = self.directions;
        settings.horizon.level_step = self.level_step;
        settings.horizon.level_offset = self.level_offset;
        settings.double_precision = self.precision == PrecisionArg::F64;
        settings.validate()?;
        Ok(settings)
    }
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum ExampleName {
    /// Sand dunes height field, diffuse and glossy spheres, a water patch, a sky map; 2 frames.
    Dunes,
    /// The analytic scene: a diffuse plane under spheres, constant white sky.
    Spheres,
}

#[derive(Args, Debug)]
pub struct ExampleArgs {
    /// Which scene.
    #[arg(value_enum)]
    pub name: ExampleName,
    /// Directory to create (must not hold a scene already).
    #[arg(long)]
    pub out: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 320)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 180)]
    pub height: u32,
}
