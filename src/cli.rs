//! Command-line options: parsed by clap into these structs, then turned into settings in
//! a separate step that checks the rules spanning several flags.

pub use crate::executor::DeviceChoice;
pub use crate::gpu::Specialisation;
pub use crate::reference::Integration;
use crate::scene::output::SampleType;
use crate::sh::ExpMethod;
use crate::shade::{default_epsilon, GlossyMethod, LightWindow, Precision, Quality, SettingsError, ShadingSettings};
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Parser, Debug)]
#[command(
    name = "logsh",
    version,
    about = "Soft environment shadows and glossy reflections for Blender G-buffers, by log-SH exponentiation"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Shade one frame of a scene directory (format v1) into a linear EXR and a PNG preview.
    Shade(ShadeArgs),
    /// Render the ground truth of one frame: exact visibility, light x visibility x BRDF integrated in f64, once with the full light and once with its SH projection.
    Reference(ReferenceArgs),
    /// Measure the speed/accuracy trade on one frame: presets and single-knob sweeps against the reference; writes CSV, JSON and an SVG plot.
    Sweep(SweepArgs),
    /// Write a procedural sample scene in format v1 (gbuffers/spheres comes from here).
    Example(ExampleArgs),
    /// Time the shading of one frame stage by stage (GPU timestamps where the adapter has them, wall time otherwise) and report megapixels per second.
    Bench(BenchArgs),
    /// Shade a sequence of frames into multi-layer EXRs (beauty and compositing passes) and PNG previews; keeps going when a frame fails.
    Render(RenderArgs),
    /// List the parts, layers, channels, sizes and sample types of an EXR file (headers only; a file cut short is refused).
    Info(InfoArgs),
    /// Recompute the beauty and every pass of frames rendered with --transfer under a turned, scaled or swapped environment, without shading again.
    Relight(RelightArgs),
    /// Serve a local web page (127.0.0.1 only) that shows the frames of a directory rendered with --transfer, fitted to the window with zoom and pan, and relights them in the browser: environment rotation (also by dragging the light's map), strength, exposure; a pixel inspector reading the EXR's values; a wipe or difference (absolute or signed, with mean and p95 error) against the Cycles render or the frame as rendered; the Sun lamps and the suns of an HDRI are shaded sharp from the scene, as logsh relight shades them. Every control has keys (`?` lists them), and the page's state is kept in its address.
    View(ViewArgs),
}

/// `--sharp-lights`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SharpLights {
    Auto,
    Off,
}

#[derive(Args, Debug)]
pub struct ReferenceArgs {
    /// Scene directory holding scene.json.
    pub scene: PathBuf,
    /// Frame to render [default: the scene's first frame, or 1].
    #[arg(long)]
    pub frame: Option<i64>,
    /// Output directory; receives reference.NNNN.{exr,png} (full light) and reference_sh.NNNN.{exr,png} (SH-projected light).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Order of the SH-projected light of the second image.
    #[arg(long, default_value_t = 4)]
    pub sh_order: usize,
    /// Convergence target per pixel, absolute (unoccluded white floor under a white sky = 1).
    #[arg(long, default_value_t = 1e-3)]
    pub tolerance: f64,
    /// Most refinements per pixel (each doubles the meridians or the samples).
    #[arg(long, default_value_t = 6)]
    pub max_level: u32,
    /// How each pixel is integrated: `sampled` (importance sampling of the map and the BRDF, exact visibility; statistical error estimate), `meridians` (deterministic, slow under a map), `auto` (meridians under a constant light, sampled otherwise).
    #[arg(long, value_enum, default_value_t = Integration::Auto)]
    pub integration: Integration,
    /// How a supersampled scene's samples are resolved to the camera's pixels (see `logsh shade --help`).
    #[arg(long, value_enum, default_value_t = crate::shade::PixelFilter::Box)]
    pub pixel_filter: crate::shade::PixelFilter,
    /// Bounces of light off the proxies (height field or ground plane, blocker spheres; diffuse, and mirrored off the spheres of a specular object), 0 to 3: paths traced with exact visibility, the truth for logsh's --bounces.
    #[arg(long, default_value_t = 0)]
    pub bounces: usize,
    /// Rays per receiver and bounce (cosine-weighted, stratified); the bounce's noise falls as one over their square root.
    #[arg(long, default_value_t = 64)]
    pub bounce_samples: usize,
    /// Glossy lobes, as `logsh shade --glossy` names them: ggx integrates GGX's BRDF with Fresnel (what the default preset reflects its suns and lamps through, and approximates for the environment by the split sum); phong and sh, the Phong lobe of Eq. 27 about the mirrored view.
    #[arg(long, value_enum, default_value_t = GlossyMethod::Ggx)]
    pub glossy: GlossyMethod,
}

#[derive(Args, Debug)]
pub struct SweepArgs {
    /// Scene directory holding scene.json.
    pub scene: PathBuf,
    /// Frame to measure [default: the scene's first frame, or 1].
    #[arg(long)]
    pub frame: Option<i64>,
    /// Output directory; receives sweep.csv, sweep.json, sweep.svg and the reference image.
    #[arg(long)]
    pub out: PathBuf,
    /// Runs per configuration; the fastest is reported.
    #[arg(long, default_value_t = 2)]
    pub repeats: usize,
    /// Convergence target of the reference, per pixel.
    #[arg(long, default_value_t = 1e-3)]
    pub tolerance: f64,
    /// How the reference integrates each pixel (see `logsh reference --help`).
    #[arg(long, value_enum, default_value_t = Integration::Auto)]
    pub integration: Integration,
    /// Where the configurations are shaded (their times are that device's).
    #[arg(long, value_enum, default_value_t = DeviceChoice::Auto)]
    pub device: DeviceChoice,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Scene directory holding scene.json.
    pub scene: PathBuf,
    /// Frame to time [default: the scene's first frame, or 1].
    #[arg(long)]
    pub frame: Option<i64>,
    /// Timed runs after one warm-up run (which also compiles the GPU program); the table shows the median of each stage.
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// What the GPU program is specialised to: full (the scene's features and the order, as shading runs), order (every feature compiled in, skipped per frame by uniform branches), none (also loop bounds and array sizes from uniforms); the last two only measure what specialisation saves.
    #[arg(long, value_enum, default_value_t = Specialisation::Full)]
    pub specialise: Specialisation,
    #[command(flatten)]
    pub shading: ShadingArgs,
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
pub enum Switch {
    On,
    Off,
}

/// The shading knobs shared by every command that shades. A knob that is not given comes
/// from `--quality`.
#[derive(Args, Debug, Clone)]
pub struct ShadingArgs {
    /// How a supersampled scene's samples are resolved to the camera's pixels: box (the mean of the pixel's samples) or blackman-harris (Blender's default filter, 1.5 px); no effect without `supersample` in scene.json.
    #[arg(long, value_enum, default_value_t = crate::shade::PixelFilter::Box)]
    pub pixel_filter: crate::shade::PixelFilter,
    /// Shade every sample of a supersampled scene, not only the pixels whose samples differ (material, object, normal or depth): what adaptive shading saves is measured against it.
    #[arg(long)]
    pub every_sample: bool,
    /// Preset of every knob below; any knob given on its own overrides it.
    #[arg(long, value_enum, default_value_t = Quality::Default)]
    pub quality: Quality,
    /// SH order n (n^2 coefficients), 3 to 8. Higher is sharper and slower [default: from --quality].
    #[arg(long)]
    pub order: Option<usize>,
    /// Log clamp eps, relative to each lobe's peak, in [1e-6, 1) [default per order, chosen by measurement: 0.15 at order 3, 0.1 at 4, 0.07 at 5-8].
    #[arg(long)]
    pub epsilon: Option<f64>,
    /// Log clamp of Phong lobes [default: per exponent and order, the eps minimising the lobe's L2 error, see docs/epsilon].
    #[arg(long)]
    pub phong_epsilon: Option<f64>,
    /// Height field: number of azimuthal directions W [default: from --quality].
    #[arg(long)]
    pub directions: Option<usize>,
    /// Height field: pyramid level step k, levels per halving of resolution, under sharp lights too [default: from --quality, finer under sharp lights: Sun or point lamps, suns taken out of the map].
    #[arg(long)]
    pub level_step: Option<f64>,
    /// Height field: pyramid level offset o, under sharp lights too [default: from --quality, finer under sharp lights].
    #[arg(long)]
    pub level_offset: Option<f64>,
    /// SH exponentiation method [default: from --quality].
    #[arg(long, value_enum)]
    pub exp: Option<ExpMethod>,
    /// Scale each sphere's log visibility by r/|c-p| (the paper's Section 4.2).
    #[arg(long, value_enum, default_value_t = Switch::Off)]
    pub ratio_attenuation: Switch,
    /// Give each sphere's cap the log depth fitted for its angular radius, and each height-field slice's horizon band the one fitted for its width (about -1 when small, log(eps) when wide), instead of log(eps) for all.
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub fitted_depths: Switch,
    /// Clamp the hemisphere behind each receiver's tangent plane in log space.
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub tangent_occlusion: Switch,
    /// Floor each quadrature node's log visibility at log(eps), so a direction behind several caps is clamped once (quad and exact only).
    #[arg(long, value_enum, default_value_t = Switch::On)]
    pub overlap_floor: Switch,
    /// Sphere clusters whose radius is at most this fraction of their distance are one cap; 0 sees every sphere.
    #[arg(long)]
    pub cluster_ratio: Option<f64>,
    /// Turn the light (environment map and suns) by this many degrees about Z, on top of the scene's own rotation: a sun at azimuth a moves to a + DEG. Point lamps stay where they are.
    #[arg(long, value_name = "DEG", default_value_t = 0.0, allow_negative_numbers = true)]
    pub light_rotation: f64,
    /// auto: take the suns out of an environment map and shade them as sharp lights (printed); off: keep the whole map in SH.
    #[arg(long, value_enum, default_value_t = SharpLights::Auto)]
    pub sharp_lights: SharpLights,
    /// Take from the diffuse light the environment's detail beyond the SH order that each sphere blocker hides: darker, sharper contact shadows under a map with structure [default: off at --quality draft, on otherwise].
    #[arg(long, value_enum)]
    pub cap_detail: Option<Switch>,
    /// Window the light's SH bands (Sloan 2008): lanczos or hann trade the ringing of a truncated projection around bright regions for blur.
    #[arg(long, value_enum, default_value_t = LightWindow::None)]
    pub light_window: LightWindow,
    /// Glossy lobes: ggx reads the environment prefiltered with the GGX lobe (what Cycles' Glossy BSDF renders) and scales it by a log-SH specular occlusion; phong does the same with the Phong lobe; sh keeps the Phong lobe in log-SH, no sharper than the order allows.
    #[arg(long, value_enum, default_value_t = GlossyMethod::Ggx)]
    pub glossy: GlossyMethod,
    /// Bounces of light off the terrain (height field or ground plane) and the sphere blockers, 0 (direct light only) to 3 [default: from --quality].
    #[arg(long)]
    pub bounces: Option<usize>,
    /// Texels per side of the grid on which the terrain's bounce light is shaded, 8 to 512 [default: from --quality].
    #[arg(long)]
    pub bounce_grid: Option<usize>,
    /// Pixels between the points where bounce light is gathered, along each axis, 1 (every pixel) to 16; the pixels between interpolate it and reflect it with their own normals [default: from --quality].
    #[arg(long)]
    pub bounce_stride: Option<usize>,
    /// Pixels per side of the blocks whose height-field and blocker visibility is computed once and interpolated between blocks, across no depth or normal edge (NS09 Section 7); the lobes, the exponentiation and the suns and lamps stay per pixel. 1 (every pixel) to 4, on either device [default: 1].
    #[arg(long)]
    pub visibility_grid: Option<usize>,
    /// Precision of the per-pixel kernel (the GPU pass is f32 only).
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    pub precision: Precision,
    /// Where to shade: auto takes a hardware GPU if there is one and otherwise the CPU, saying which and why; gpu takes any adapter (lavapipe included) or fails.
    #[arg(long, value_enum, default_value_t = DeviceChoice::Auto)]
    pub device: DeviceChoice,
}

impl ShadingArgs {
    /// How a supersampled scene is shaded and resolved.
    pub fn resolving(&self) -> crate::shade::Resolving {
        crate::shade::Resolving { filter: self.pixel_filter, every_sample: self.every_sample }
    }

    /// The settings these flags describe, checked.
    pub fn settings(&self) -> Result<ShadingSettings, SettingsError> {
        let mut settings = self.quality.settings();
        if let Some(order) = self.order {
            settings.order = order;
            settings.epsilon = default_epsilon(order);
        }
        if let Some(epsilon) = self.epsilon {
            settings.epsilon = epsilon;
        }
        settings.phong_epsilon = self.phong_epsilon;
        if let Some(exp) = self.exp {
            settings.exp = exp;
        }
        settings.ratio_attenuation = self.ratio_attenuation == Switch::On;
        settings.fitted_depths = self.fitted_depths == Switch::On;
        settings.tangent_occlusion = self.tangent_occlusion == Switch::On;
        settings.overlap_floor = self.overlap_floor == Switch::On;
        settings.sharp_lights = self.sharp_lights == SharpLights::Auto;
        if let Some(switch) = self.cap_detail {
            settings.cap_detail = switch == Switch::On;
        }
        settings.light_window = self.light_window;
        settings.glossy = self.glossy;
        if let Some(ratio) = self.cluster_ratio {
            settings.cluster_ratio = ratio;
        }
        if let Some(w) = self.directions {
            settings.horizon.directions = w;
        }
        if let Some(k) = self.level_step {
            settings.horizon.level_step = k;
        }
        if let Some(o) = self.level_offset {
            settings.horizon.level_offset = o;
        }
        if self.level_step.is_some() || self.level_offset.is_some() {
            settings.lamp_levels = None;
        }
        if let Some(bounces) = self.bounces {
            settings.bounce.bounces = bounces;
        }
        if let Some(grid) = self.bounce_grid {
            settings.bounce.grid = grid;
        }
        if let Some(stride) = self.bounce_stride {
            settings.bounce.stride = stride;
        }
        if let Some(grid) = self.visibility_grid {
            settings.visibility_grid = grid;
        }
        settings.precision = self.precision;
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
    /// G-buffer samples per pixel along each axis, 1 to 4 (as the exporter's --supersample).
    #[arg(long, default_value_t = 1)]
    pub supersample: u32,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene directory holding scene.json.
    pub scene: PathBuf,
    /// Frames to render, as farm managers and oiiotool write them: 1-240, 1-240x2, 1,5,10-20, 1..10 [default: the scene's frames].
    #[arg(long, value_parser = clap::value_parser!(crate::render::frames::FrameSpec))]
    pub frames: Option<crate::render::frames::FrameSpec>,
    /// Output directory; receives NAME.NNNN.exr (multi-layer: beauty, passes, P, N) and NAME.NNNN.png, NAME from --name.
    #[arg(long)]
    pub out: PathBuf,
    /// File name stem of the outputs.
    #[arg(long, default_value = "render")]
    pub name: String,
    /// Leave frames whose EXR and PNG are already complete untouched (resume a stopped render).
    #[arg(long)]
    pub skip_existing: bool,
    /// Worker threads for the pixels of a frame [default: one per core].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Progress report: a bar on a terminal, plain lines in logs, JSON lines on stdout for scripts.
    #[arg(long, value_enum, default_value_t = crate::render::progress::ProgressMode::Auto)]
    pub progress: crate::render::progress::ProgressMode,
    /// Storage of the colour passes and visibility terms (P and N are always float); half stops at 65504 rather than infinity.
    #[arg(long, value_enum, default_value_t = SampleType::Half)]
    pub colour_type: SampleType,
    /// Also write each pixel's transfer vectors (diffuse and specular, order^2 coefficients each), its colours and glossy lookup as EXR layers, for `logsh relight` and `logsh view`; shaded on the CPU.
    #[arg(long)]
    pub transfer: bool,
    /// Shade, resolve and write each frame in bands of this many G-buffer rows (rounded up to whole blocks), so that a frame of any size holds one band in memory; the images are the same. 0 shades every frame whole [default: bands of about 4 million G-buffer samples; smaller frames whole].
    #[arg(long)]
    pub band_rows: Option<usize>,
    #[command(flatten)]
    pub shading: ShadingArgs,
}

#[derive(Args, Debug)]
pub struct RelightArgs {
    /// Frames rendered with `logsh render --transfer`.
    #[arg(required = true)]
    pub frames: Vec<PathBuf>,
    /// Relight with this environment map (EXR or HDR, oriented as a Blender World's Environment Texture) instead of the rendered light, turned as the render turned its light (its --light-rotation), then by --light-rotation.
    #[arg(long)]
    pub light: Option<PathBuf>,
    /// Turn the light by this many degrees about Z, on top of the rendered turn: the map and, with --sun-lamps turn, the scene's Sun lamps, as `logsh render --light-rotation` turns them. Point lamps stay as rendered.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub light_rotation: f64,
    /// What --light-rotation does to the scene's Sun lamps: `turn` shades them again, turned, from the scene the frame was rendered from (as `logsh render --light-rotation` does; it costs about a Sun lamp's share of a render); `keep` leaves them and their shadows as rendered.
    #[arg(long, value_enum, default_value_t = SunLamps::Turn)]
    pub sun_lamps: SunLamps,
    /// Strength of the map [default: the rendered strength; 1 with --light]; scales a constant or SH light too.
    #[arg(long, allow_negative_numbers = true, value_parser = relight_strength)]
    pub strength: Option<f32>,
    /// Output directory; receives each frame's relit EXR (beauty and passes, same file name), a PNG preview and FRAME.light.json (the light's SH vector).
    #[arg(long)]
    pub out: PathBuf,
    /// Storage of the colour passes and visibility terms (P and N are always float); half stops at 65504 rather than infinity.
    #[arg(long, value_enum, default_value_t = SampleType::Half)]
    pub colour_type: SampleType,
    /// auto: as the frame was rendered (its --sharp-lights): the suns taken out of the map are shaded sharp again, with their shadows, from the scene it was rendered from (about a sun's share of a render); off: the whole map in SH, its suns' shadows soft, no scene read.
    #[arg(long, value_enum, default_value_t = SharpLights::Auto)]
    pub sharp_lights: SharpLights,
    /// Progress report: a bar on a terminal, plain lines in logs, JSON lines on stdout for scripts (as `render`'s).
    #[arg(long, value_enum, default_value_t = crate::render::progress::ProgressMode::Auto)]
    pub progress: crate::render::progress::ProgressMode,
}

/// `--sun-lamps`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SunLamps {
    Turn,
    Keep,
}

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// Directory of frames rendered with `logsh render --transfer`; frames written into it while the server runs join the page's list at its end.
    pub dir: PathBuf,
    /// Port on 127.0.0.1 (0: any free port, printed on start).
    #[arg(long, default_value_t = 8642)]
    pub port: u16,
    /// Do not open the page in a browser.
    #[arg(long)]
    pub no_open: bool,
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// EXR files to describe.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `--strength` of `logsh relight`: a finite value from 0 to the largest f32, refused as
/// typed (an f32 read 1e39 as infinity, and the message named a value no one typed).
fn relight_strength(text: &str) -> Result<f32, String> {
    match text.trim().parse::<f64>() {
        Ok(value) if value.is_finite() && (0.0..=f64::from(f32::MAX)).contains(&value) => Ok(value as f32),
        Ok(_) => Err(format!("give a finite value from 0 to {:e}", f32::MAX)),
        Err(e) => Err(e.to_string()),
    }
}
