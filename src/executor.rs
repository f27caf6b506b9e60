//! Where a frame is shaded: `--device` resolved to the CPU executor ([`crate::shade::cpu`])
//! or the GPU one ([`crate::gpu`]), and the fall-back from the second to the first.
//!
//! `auto` takes a hardware GPU only: a software adapter (lavapipe, llvmpipe, WARP) runs
//! the shading pass on the CPU, about twice as slowly as the CPU executor on the same
//! cores, so it is used only when asked for by `--device gpu`. Under `auto`, a frame the
//! adapter cannot shade correctly goes to the CPU executor instead of failing.
//!
//! The library prints nothing: what the user should know about the choice and every
//! fall-back is queued as a [`Notice`] for the command line to print
//! ([`Executor::take_notices`]).

use crate::gpu::{Gpu, GpuError, Specialisation};
use crate::scene::{Frame, Scene};
use crate::shade::{
    adaptive, bounce, FramePlan, Outputs, Precision, Resolve, Resolving, SettingsError, ShadeError, Shaded,
    ShadedFrame, ShadedPasses, ShadingSettings,
};
use crate::timing::{Clock, StageTimings};
use std::sync::Mutex;

/// Where shading runs (`--device`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceChoice {
    /// A hardware GPU if there is one, the CPU otherwise (saying which, and why).
    Auto,
    /// A GPU adapter, software ones such as lavapipe included, or an error.
    Gpu,
    /// The CPU.
    Cpu,
}

/// Something the user should know about where frames are shaded: which executor was
/// chosen and why, or that a frame fell back to the CPU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Notice(pub String);

impl std::fmt::Display for Notice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ExecutorError {
    #[error(transparent)]
    Shade(#[from] ShadeError),
    #[error(transparent)]
    Gpu(GpuError),
}

impl From<GpuError> for ExecutorError {
    fn from(error: GpuError) -> Self {
        match error {
            GpuError::Shade(e) => Self::Shade(e),
            e => Self::Gpu(e),
        }
    }
}

enum Device {
    Cpu,
    /// `fallback`: chosen by `--device auto`, so a frame the adapter cannot shade
    /// correctly goes to the CPU executor instead of failing.
    Gpu {
        gpu: Box<Gpu>,
        fallback: bool,
    },
}

/// The executor `--device` chose.
pub struct Executor {
    device: Device,
    notices: Mutex<Vec<Notice>>,
}

fn cpu_description() -> String {
    format!("cpu ({} threads)", rayon::current_num_threads())
}

impl Executor {
    /// The CPU executor.
    pub fn cpu() -> Self {
        Self::on(Device::Cpu)
    }

    fn on(device: Device) -> Self {
        Self { device, notices: Mutex::new(Vec::new()) }
    }

    /// Resolves `--device`. `auto` takes a hardware GPU, and otherwise the CPU with a
    /// notice saying why; `gpu` takes any adapter, software included, or fails.
    pub fn select(choice: DeviceChoice, settings: &ShadingSettings) -> Result<Self, ExecutorError> {
        let on_cpu = |why: String| {
            let executor = Self::cpu();
            let threads = rayon::current_num_threads();
            executor.notify(format!("--device auto: shading on the CPU ({threads} threads), {why}"));
            executor
        };
        match choice {
            DeviceChoice::Cpu => Ok(Self::cpu()),
            DeviceChoice::Gpu => {
                if settings.precision == Precision::F64 {
                    return Err(GpuError::double_precision().into());
                }
                Ok(Self::on(Device::Gpu { gpu: Box::new(Gpu::new()?), fallback: false }))
            }
            DeviceChoice::Auto if settings.precision == Precision::F64 => {
                Ok(on_cpu("since the GPU pass runs in f32 and --precision f64 was asked".into()))
            }
            DeviceChoice::Auto => match Gpu::new_hardware() {
                Ok(gpu) => {
                    let executor = Self::on(Device::Gpu { gpu: Box::new(gpu), fallback: true });
                    executor.notify(format!("--device auto: shading on {}, a hardware GPU", executor.describe()));
                    Ok(executor)
                }
                Err(e) => Ok(on_cpu(format!("since {e}"))),
            },
        }
    }

    /// Whether frames are shaded on a GPU.
    pub fn on_gpu(&self) -> bool {
        matches!(self.device, Device::Gpu { .. })
    }

    /// "cpu (N threads)" or "gpu: adapter".
    pub fn describe(&self) -> String {
        match &self.device {
            Device::Cpu => cpu_description(),
            Device::Gpu { gpu, .. } => format!("gpu: {}", gpu.adapter()),
        }
    }

    /// The notices queued since the last call, oldest first.
    pub fn take_notices(&self) -> Vec<Notice> {
        std::mem::take(&mut *self.notices.lock().expect("notice list"))
    }

    fn notify(&self, message: String) {
        self.notices.lock().expect("notice list").push(Notice(message));
    }

    /// Shades `job` into `O`, the beauty ([`ShadedFrame`]) or the passes
    /// ([`ShadedPasses`]), adding each stage's time to `timings` and naming the executor
    /// that ran there.
    ///
    /// A supersampled frame with [`ShadeJob::resolving`] is shaded where its samples
    /// differ ([`adaptive`], unless `every_sample`), its bounce light ([`Self::bounce`])
    /// gathered over every sample, then resolved ([`crate::shade::resolve`]). The stages
    /// are the executor's own (GPU timestamps where the adapter has them), then
    /// "adaptive" (choosing, packing and scattering the samples), "bounce" and "resolve"
    /// on the wall clock.
    pub fn shade<O: ShadedOutputs>(&self, job: &ShadeJob, timings: &mut StageTimings) -> Result<O, ExecutorError> {
        timings.device = self.describe();
        timings.on_gpu = self.on_gpu();
        // The bounce gather reads the visibility pass.
        let outputs = if job.settings.bounce.bounces > 0 { Outputs::Passes } else { O::OUTPUTS };
        let (scene, frame) = (job.scene, job.frame);
        let n = frame.supersample.max(1);
        let adaptive = match job.resolving {
            Some(resolving) if n > 1 => {
                check_grid_keeps_pixels(job.settings, n, resolving)?;
                !resolving.every_sample
            }
            _ => false,
        };
        let mut shaded = if adaptive {
            let started = std::time::Instant::now();
            let selection = adaptive::select(frame);
            let select_time = started.elapsed();
            let packed = self.shade_direct(job.with_frame(&selection.packed), outputs, timings)?;
            let started = std::time::Instant::now();
            let shaded = match packed {
                Shaded::Beauty(packed) => Shaded::Beauty(ShadedFrame {
                    rgba: selection.scatter_rgba(&scene.materials, frame, &packed.rgba),
                    width: frame.gbuffer.width,
                    height: frame.gbuffer.height,
                }),
                Shaded::Passes(packed) => Shaded::Passes(selection.scatter_passes(&scene.materials, frame, &packed)),
            };
            timings.add("adaptive", (select_time + started.elapsed()).as_secs_f64() * 1e3, Clock::Wall);
            timings.samples = Some((selection.shaded, selection.samples));
            shaded
        } else {
            self.shade_direct(*job, outputs, timings)?
        };
        if let Shaded::Passes(passes) = &mut shaded {
            let started = std::time::Instant::now();
            if let Some(indirect) = self.bounce(job.bounce, scene, frame, job.settings, &passes.visibility)? {
                passes.add_indirect(indirect);
                timings.add_wall("bounce", started);
            }
        }
        if let (Some(resolving), true) = (job.resolving, n > 1) {
            let started = std::time::Instant::now();
            let g = &frame.gbuffer;
            let resolve = Resolve::new(n, g.width / n, g.height / n, resolving.filter);
            shaded = match shaded {
                Shaded::Beauty(beauty) => Shaded::Beauty(ShadedFrame {
                    width: g.width / n,
                    height: g.height / n,
                    rgba: resolve.filter(&beauty.rgba),
                }),
                Shaded::Passes(passes) => Shaded::Passes(resolve.passes(&passes)),
            };
            timings.add_wall("resolve", started);
        }
        Ok(O::from_shaded(shaded))
    }

    /// The bounce light of `frame` ([`bounce`]), `None` where nothing bounces: from
    /// surroundings planned from its own pixels (their secondary points shaded with direct
    /// light on this executor, then gathered on the CPU), or from those `bounce` gives.
    /// `visibility`: the frame's `visibility` pass.
    pub fn bounce(
        &self,
        bounce: Bounce,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        visibility: &[f32],
    ) -> Result<Option<bounce::IndirectParts>, ExecutorError> {
        let planned;
        let surroundings = match bounce {
            Bounce::Given(surroundings) => surroundings,
            Bounce::OfFrame => match bounce::SurroundingsPlan::new(scene, frame, &settings.bounce)? {
                Some(plan) => {
                    planned = self.light_surroundings(scene, plan, settings)?;
                    Some(&planned)
                }
                None => None,
            },
        };
        // A supersampled G-buffer gathers as densely per camera pixel as a plain one.
        let stride = settings.bounce.stride * frame.supersample.max(1);
        Ok(surroundings.map(|surroundings| surroundings.indirect(scene, frame, stride, Some(visibility))))
    }

    /// The surroundings of `plan` lit: their secondary points shaded with direct light on
    /// this executor, then the bounces before the last gathered on the CPU.
    pub fn light_surroundings(
        &self,
        scene: &Scene,
        plan: bounce::SurroundingsPlan,
        settings: &ShadingSettings,
    ) -> Result<bounce::Surroundings, ExecutorError> {
        // The secondary points are packed side by side, not neighbours: each is shaded alone.
        let one_by_one = ShadingSettings { visibility_grid: 1, ..*settings };
        let points_scene = plan.points_scene(scene);
        let job = ShadeJob::new(&points_scene, plan.points(), &one_by_one);
        let direct = self.shade_direct(job, Outputs::Passes, &mut StageTimings::default())?;
        let direct = direct.into_passes().expect("shaded into passes");
        let sky = crate::shade::plan::environment_luminance(&one_by_one, &points_scene, plan.points());
        Ok(plan.lit(scene, &direct.diffuse, &direct.visibility, &sky))
    }

    /// Direct light at every pixel of `job.frame`, its samples as they are: the frame
    /// planned once ([`FramePlan`]), then shaded on the GPU, or on the CPU by choice or as
    /// the fall-back of `--device auto` for a frame the adapter cannot shade correctly.
    fn shade_direct(
        &self,
        job: ShadeJob,
        outputs: Outputs,
        timings: &mut StageTimings,
    ) -> Result<Shaded, ExecutorError> {
        let plan = FramePlan::new(job.scene, job.frame, job.settings)?;
        let mut own = plan.timings.clone();
        let shaded = match &self.device {
            Device::Cpu => crate::shade::cpu::shade_plan(&plan, outputs, &mut own),
            Device::Gpu { gpu, fallback } => match gpu.shade_plan(&plan, outputs, job.specialisation, &mut own) {
                Err(e @ GpuError::LoopBudget { .. }) if *fallback => {
                    self.notify(format!("--device auto: shading frame {} on the CPU: {e}", job.frame.number));
                    (timings.device, timings.on_gpu) = (cpu_description(), false);
                    own = plan.timings.clone();
                    crate::shade::cpu::shade_plan(&plan, outputs, &mut own)
                }
                other => other?,
            },
        };
        timings.add_all(&own);
        Ok(shaded)
    }
}

/// A frame to shade and how: everything [`Executor::shade`] needs but the outputs.
#[derive(Clone, Copy)]
pub struct ShadeJob<'a> {
    pub scene: &'a Scene,
    pub frame: &'a Frame,
    pub settings: &'a ShadingSettings,
    /// How a supersampled frame is resolved to the camera's pixels; `None` shades and
    /// returns every sample as a pixel (`bench`, `sweep`).
    pub resolving: Option<Resolving>,
    /// Where its bounce light comes from.
    pub bounce: Bounce<'a>,
    /// Below [`Specialisation::Full`] only on the GPU, to measure what specialisation
    /// saves (`bench --specialise`).
    pub specialisation: Specialisation,
}

impl<'a> ShadeJob<'a> {
    /// `frame` of `scene` resolved with the default filter, bounce light from its own
    /// pixels, the GPU program fully specialised.
    pub fn new(scene: &'a Scene, frame: &'a Frame, settings: &'a ShadingSettings) -> Self {
        Self {
            scene,
            frame,
            settings,
            resolving: Some(Resolving::default()),
            bounce: Bounce::OfFrame,
            specialisation: Specialisation::Full,
        }
    }

    fn with_frame(self, frame: &'a Frame) -> Self {
        Self { frame, ..self }
    }
}

/// What [`Executor::shade`] returns: [`ShadedFrame`] (the beauty) or [`ShadedPasses`].
pub trait ShadedOutputs: Sized {
    const OUTPUTS: Outputs;
    /// `shaded` is in passes wherever `OUTPUTS` asks for them.
    fn from_shaded(shaded: Shaded) -> Self;
}

impl ShadedOutputs for ShadedFrame {
    const OUTPUTS: Outputs = Outputs::Beauty;
    fn from_shaded(shaded: Shaded) -> Self {
        shaded.into_beauty()
    }
}

impl ShadedOutputs for ShadedPasses {
    const OUTPUTS: Outputs = Outputs::Passes;
    fn from_shaded(shaded: Shaded) -> Self {
        shaded.into_passes().expect("shaded into passes, as OUTPUTS asks")
    }
}

/// Where a frame's bounce light comes from: surroundings planned from its own pixels, or
/// given (those of the whole frame a band belongs to, [`crate::render::bands`]; `None`:
/// nothing bounces).
#[derive(Clone, Copy)]
pub enum Bounce<'a> {
    OfFrame,
    Given(Option<&'a bounce::Surroundings>),
}

/// A visibility grid interpolates between neighbouring pixels, which the adaptive
/// selection of a supersampled frame's samples does not keep ([`adaptive`]): refused
/// there, with the way out.
fn check_grid_keeps_pixels(
    settings: &ShadingSettings,
    supersample: usize,
    resolving: Resolving,
) -> Result<(), ShadeError> {
    if settings.visibility_grid > 1 && supersample > 1 && !resolving.every_sample {
        return Err(ShadeError::Settings(SettingsError::VisibilityGridWithout {
            grid: settings.visibility_grid,
            why: "the adaptive selection of a supersampled frame's samples does not keep them side by side",
            instead: "add --every-sample, or leave --visibility-grid at 1",
        }));
    }
    Ok(())
}
