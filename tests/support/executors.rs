//! Each executor run on its own, below [`logsh::executor::Executor`]: the frame planned,
//! then shaded on the CPU or on a given GPU, its samples as they are and direct light
//! only, as the comparisons between the two executors need.

use logsh::executor::{Executor, ShadeJob};
use logsh::gpu::{Gpu, GpuError, Specialisation};
use logsh::scene::{Frame, Scene};
use logsh::shade::{cpu, FramePlan, Outputs, Resolving, ShadeError, ShadedFrame, ShadedPasses, ShadingSettings};
use logsh::timing::StageTimings;

/// The beauty, on the CPU.
pub fn cpu_beauty(scene: &Scene, frame: &Frame, settings: &ShadingSettings) -> Result<ShadedFrame, ShadeError> {
    let plan = FramePlan::new(scene, frame, settings)?;
    Ok(cpu::shade_plan(&plan, Outputs::Beauty, &mut StageTimings::default()).into_beauty())
}

/// The passes, on the CPU.
pub fn cpu_passes(scene: &Scene, frame: &Frame, settings: &ShadingSettings) -> Result<ShadedPasses, ShadeError> {
    let plan = FramePlan::new(scene, frame, settings)?;
    let shaded = cpu::shade_plan(&plan, Outputs::Passes, &mut StageTimings::default());
    Ok(shaded.into_passes().expect("shaded into passes"))
}

/// The beauty, on `gpu`, its program specialised to the frame.
pub fn gpu_beauty(
    gpu: &Gpu,
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
) -> Result<ShadedFrame, GpuError> {
    Ok(gpu_beauty_timed(gpu, scene, frame, settings, Specialisation::Full)?.0)
}

/// The beauty, on `gpu`, with its program specialised as far as `specialisation`, and
/// its stages' times.
pub fn gpu_beauty_timed(
    gpu: &Gpu,
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
    specialisation: Specialisation,
) -> Result<(ShadedFrame, StageTimings), GpuError> {
    let plan = FramePlan::new(scene, frame, settings)?;
    let mut timings = plan.timings.clone();
    let shaded = gpu.shade_plan(&plan, Outputs::Beauty, specialisation, &mut timings)?;
    Ok((shaded.into_beauty(), timings))
}

/// The passes, on `gpu`.
pub fn gpu_passes(
    gpu: &Gpu,
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
) -> Result<ShadedPasses, GpuError> {
    let plan = FramePlan::new(scene, frame, settings)?;
    let shaded = gpu.shade_plan(&plan, Outputs::Passes, Specialisation::Full, &mut StageTimings::default())?;
    Ok(shaded.into_passes().expect("shaded into passes"))
}

/// The passes `logsh render` writes, bounce light included, on `executor`.
pub fn rendered_passes(
    executor: &Executor,
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
) -> Result<ShadedPasses, logsh::executor::ExecutorError> {
    executor.shade(&ShadeJob::new(scene, frame, settings), &mut StageTimings::default())
}

/// The beauty `logsh shade` writes, resolved with `resolving`, and its stages' times.
pub fn resolved_beauty(
    executor: &Executor,
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
    resolving: Resolving,
) -> Result<(ShadedFrame, StageTimings), logsh::executor::ExecutorError> {
    let mut timings = StageTimings::default();
    let job = ShadeJob { resolving: Some(resolving), ..ShadeJob::new(scene, frame, settings) };
    Ok((executor.shade(&job, &mut timings)?, timings))
}
