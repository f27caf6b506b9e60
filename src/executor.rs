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
    adaptive, bounce, Precision, Resolve, Resolving, SettingsError, ShadeError, ShadedFrame, ShadedPasses,
    ShadingSettings,
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

    /// Runs `on_gpu` on the GPU, or `on_cpu` on the CPU executor: by choice, or as the
    /// fall-back of `--device auto` for a frame the adapter cannot shade correctly.
    fn run<R>(
        &self,
        frame: &Frame,
        on_gpu: impl FnOnce(&Gpu) -> Result<R, GpuError>,
        on_cpu: impl FnOnce() -> Result<R, ShadeError>,
    ) -> Result<R, ExecutorError> {
        match &self.device {
            Device::Cpu => Ok(on_cpu()?),
            Device::Gpu { gpu, fallback } => match on_gpu(gpu) {
                Err(e @ GpuError::LoopBudget { .. }) if *fallback => {
                    self.notify(format!("--device auto: shading frame {} on the CPU: {e}", frame.number));
                    Ok(on_cpu()?)
                }
                other => Ok(other?),
            },
        }
    }

    pub fn shade(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
    ) -> Result<ShadedFrame, ExecutorError> {
        Ok(self.shade_timed(scene, frame, settings, Specialisation::Full)?.0)
    }

    /// The frame's compositing passes and visibility terms (`logsh render`), bounce light
    /// included.
    pub fn shade_passes(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
    ) -> Result<ShadedPasses, ExecutorError> {
        Ok(self.shade_passes_timed(scene, frame, settings, Resolving::default(), Bounce::OfFrame)?.0)
    }

    /// [`shade_passes`](Self::shade_passes) with direct light only.
    fn shade_direct_passes(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
    ) -> Result<ShadedPasses, ExecutorError> {
        self.run(
            frame,
            |gpu| gpu.shade_frame_passes(scene, frame, settings),
            || crate::shade::shade_frame_passes(scene, frame, settings),
        )
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
        let direct = self.shade_direct_passes(scene, plan.points(), &one_by_one)?;
        Ok(plan.lit(scene, &direct.diffuse, &direct.visibility))
    }

    /// [`shade_passes`](Self::shade_passes) at the camera's resolution: a supersampled
    /// frame shaded where its samples differ ([`crate::shade::adaptive`], unless
    /// `resolving.every_sample`), its bounce light ([`Self::bounce`]) gathered over every
    /// sample, then resolved ([`crate::shade::resolve`]).
    pub fn shade_passes_resolved(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        resolving: Resolving,
        bounce: Bounce,
    ) -> Result<ShadedPasses, ExecutorError> {
        Ok(self.shade_passes_timed(scene, frame, settings, resolving, bounce)?.0)
    }

    /// [`shade_passes_resolved`](Self::shade_passes_resolved), timed: the stages "shade",
    /// "adaptive" (choosing, packing and scattering the samples), "bounce" and "resolve",
    /// on the wall clock.
    fn shade_passes_timed(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        resolving: Resolving,
        bounce: Bounce,
    ) -> Result<(ShadedPasses, StageTimings), ExecutorError> {
        let mut timings = StageTimings {
            device: self.describe(),
            on_gpu: matches!(self.device, Device::Gpu { .. }),
            ..Default::default()
        };
        let n = frame.supersample.max(1);
        check_grid_keeps_pixels(settings, n, resolving)?;
        let started = std::time::Instant::now();
        let mut passes = if n == 1 || resolving.every_sample {
            let passes = self.shade_direct_passes(scene, frame, settings)?;
            timings.add_wall("shade", started);
            passes
        } else {
            let selection = adaptive::select(frame);
            let select_time = started.elapsed();
            let started = std::time::Instant::now();
            let packed = self.shade_direct_passes(scene, &selection.packed, settings)?;
            timings.add_wall("shade", started);
            let started = std::time::Instant::now();
            let passes = selection.scatter_passes(&scene.materials, frame, &packed);
            timings.add("adaptive", (select_time + started.elapsed()).as_secs_f64() * 1e3, Clock::Wall);
            timings.samples = Some((selection.shaded, selection.samples));
            passes
        };
        let started = std::time::Instant::now();
        if let Some(indirect) = self.bounce(bounce, scene, frame, settings, &passes.visibility)? {
            passes.add_indirect(indirect);
            timings.add_wall("bounce", started);
        }
        if n == 1 {
            return Ok((passes, timings));
        }
        let g = &frame.gbuffer;
        let started = std::time::Instant::now();
        let passes = Resolve::new(n, g.width / n, g.height / n, resolving.filter).passes(&passes);
        timings.add_wall("resolve", started);
        Ok((passes, timings))
    }

    /// [`shade_timed`](Self::shade_timed) at the camera's resolution, as
    /// [`shade_passes_resolved`](Self::shade_passes_resolved) shades and resolves.
    pub fn shade_resolved_timed(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        resolving: Resolving,
    ) -> Result<(ShadedFrame, StageTimings), ExecutorError> {
        let n = frame.supersample;
        if n <= 1 {
            return self.shade_timed(scene, frame, settings, Specialisation::Full);
        }
        check_grid_keeps_pixels(settings, n, resolving)?;
        if settings.bounce.bounces > 0 {
            let (passes, timings) = self.shade_passes_timed(scene, frame, settings, resolving, Bounce::OfFrame)?;
            return Ok((ShadedFrame { width: passes.width, height: passes.height, rgba: passes.beauty }, timings));
        }
        let (rgba, mut timings) = if resolving.every_sample {
            let (shaded, timings) = self.shade_direct_timed(scene, frame, settings, Specialisation::Full)?;
            (shaded.rgba, timings)
        } else {
            let started = std::time::Instant::now();
            let selection = adaptive::select(frame);
            let select_time = started.elapsed();
            let (shaded, mut timings) =
                self.shade_direct_timed(scene, &selection.packed, settings, Specialisation::Full)?;
            let started = std::time::Instant::now();
            let rgba = selection.scatter_rgba(&scene.materials, frame, &shaded.rgba);
            timings.add("adaptive", (select_time + started.elapsed()).as_secs_f64() * 1e3, Clock::Wall);
            timings.samples = Some((selection.shaded, selection.samples));
            (rgba, timings)
        };
        let g = &frame.gbuffer;
        let (width, height) = (g.width / n, g.height / n);
        let started = std::time::Instant::now();
        let rgba = Resolve::new(n, width, height, resolving.filter).filter(&rgba);
        timings.add_wall("resolve", started);
        Ok((ShadedFrame { width, height, rgba }, timings))
    }

    /// Shades and times each stage. Without bounce light the stages are the executor's
    /// own (GPU timestamps where the adapter has them; `specialisation` only matters on
    /// the GPU, see [`Gpu::shade_frame_timed`]); with it, the frame is shaded into its
    /// passes, whose visibility the bounce reads, and timed on the wall clock as "shade"
    /// and "bounce". The timings name the executor that ran.
    pub fn shade_timed(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        specialisation: Specialisation,
    ) -> Result<(ShadedFrame, StageTimings), ExecutorError> {
        if settings.bounce.bounces == 0 {
            return self.shade_direct_timed(scene, frame, settings, specialisation);
        }
        let (passes, timings) =
            self.shade_passes_timed(scene, frame, settings, Resolving::default(), Bounce::OfFrame)?;
        Ok((ShadedFrame { width: passes.width, height: passes.height, rgba: passes.beauty }, timings))
    }

    /// [`shade_timed`](Self::shade_timed) with direct light only.
    fn shade_direct_timed(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        specialisation: Specialisation,
    ) -> Result<(ShadedFrame, StageTimings), ExecutorError> {
        self.run(
            frame,
            |gpu| {
                let (shaded, mut timings) = gpu.shade_frame_timed(scene, frame, settings, specialisation)?;
                timings.device = self.describe();
                timings.on_gpu = true;
                Ok((shaded, timings))
            },
            || {
                let (shaded, mut timings) = crate::shade::shade_frame_timed(scene, frame, settings)?;
                timings.device = cpu_description();
                Ok((shaded, timings))
            },
        )
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
