//! `logsh bench`: one warm-up run, then timed runs of the same frame; the median of
//! each stage, the median wall time of a frame and megapixels per second.

use crate::executor::{Executor, ShadeJob};
use crate::gpu::Specialisation;
use crate::scene::{Frame, GBuffer, Scene};
use crate::shade::{ShadedFrame, ShadingSettings};
use crate::timing::{Clock, Stage, StageTimings};
use std::time::Instant;

/// Shades `frame` once to warm up (compiling the GPU program), then `repeats` times
/// (at least once), timing each run.
pub fn measure(
    executor: &Executor,
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
    specialisation: Specialisation,
    repeats: usize,
) -> Result<BenchReport, crate::executor::ExecutorError> {
    // Every sample of a supersampled frame, as it is: what shading a pixel costs.
    let job = ShadeJob { resolving: None, specialisation, ..ShadeJob::new(scene, frame, settings) };
    executor.shade::<ShadedFrame>(&job, &mut StageTimings::default())?;
    let mut runs = Vec::new();
    let mut walls = Vec::new();
    for _ in 0..repeats.max(1) {
        let started = Instant::now();
        let mut timings = StageTimings::default();
        executor.shade::<ShadedFrame>(&job, &mut timings)?;
        walls.push(started.elapsed().as_secs_f64() * 1e3);
        runs.push(timings);
    }
    Ok(BenchReport::new(&frame.gbuffer, frame.number, settings, specialisation, &runs, &walls))
}

/// What `logsh bench` reports: the median of each stage over the timed runs, the median
/// wall time of a whole frame, and megapixels per second.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchReport {
    pub device: String,
    pub frame: i64,
    pub width: usize,
    pub height: usize,
    pub order: usize,
    pub exp: String,
    pub directions: usize,
    /// What the GPU program was specialised to; `None` where the runs were shaded on the
    /// CPU, which has no program to specialise.
    pub specialisation: Option<Specialisation>,
    pub runs: usize,
    pub stages: Vec<Stage>,
    /// Median wall time of one whole frame, host work included.
    pub frame_milliseconds: f64,
    /// Pixels per second over the whole frame.
    pub megapixels_per_second: f64,
    /// Pixels per second of the shading stage alone.
    pub shade_megapixels_per_second: f64,
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    match values.len() {
        0 => 0.0,
        n if n % 2 == 1 => values[n / 2],
        n => 0.5 * (values[n / 2 - 1] + values[n / 2]),
    }
}

impl BenchReport {
    pub fn new(
        gbuffer: &GBuffer,
        frame: i64,
        settings: &ShadingSettings,
        specialisation: Specialisation,
        runs: &[StageTimings],
        walls: &[f64],
    ) -> Self {
        let mut stages: Vec<Stage> = Vec::new();
        for run in runs {
            for stage in &run.stages {
                if !stages.iter().any(|s| s.name == stage.name) {
                    stages.push(stage.clone());
                }
            }
        }
        for stage in &mut stages {
            stage.milliseconds = median(
                runs.iter()
                    .map(|r| r.stages.iter().find(|s| s.name == stage.name).map_or(0.0, |s| s.milliseconds))
                    .collect(),
            );
        }
        let pixels = (gbuffer.width * gbuffer.height) as f64;
        let frame_milliseconds = median(walls.to_vec());
        let shade = stages.iter().find(|s| s.name == "shade").map_or(frame_milliseconds, |s| s.milliseconds);
        let per_second = |ms: f64| if ms > 0.0 { pixels / (ms * 1e3) } else { 0.0 };
        Self {
            device: runs.first().map(|r| r.device.clone()).unwrap_or_default(),
            frame,
            width: gbuffer.width,
            height: gbuffer.height,
            order: settings.order,
            exp: format!("{:?}", settings.exp).to_lowercase(),
            directions: settings.horizon.directions,
            specialisation: (!runs.is_empty() && runs.iter().all(|r| r.on_gpu)).then_some(specialisation),
            runs: runs.len(),
            stages,
            frame_milliseconds,
            megapixels_per_second: per_second(frame_milliseconds),
            shade_megapixels_per_second: per_second(shade),
        }
    }

    /// The report as a text table.
    pub fn table(&self) -> String {
        let mut out = format!(
            "{}x{} frame {}, order {}, exp {}, W {}, {}on {}\nmedian of {} run(s)\n\n{:<20} {:>12}  clock\n",
            self.width,
            self.height,
            self.frame,
            self.order,
            self.exp,
            self.directions,
            match self.specialisation {
                Some(Specialisation::Full) => "fully specialised program, ",
                Some(Specialisation::Order) => "order-specialised program, ",
                Some(Specialisation::None) => "unspecialised program, ",
                None => "",
            },
            self.device,
            self.runs,
            "stage",
            "ms"
        );
        for s in &self.stages {
            let clock = match s.clock {
                Clock::Gpu => "gpu timestamps",
                Clock::Wall => "wall",
            };
            out += &format!("{:<20} {:>12.3}  {clock}\n", s.name, s.milliseconds);
        }
        out += &format!(
            "{:<20} {:>12.3}  wall\n\n{:.2} Mpixel/s per frame, {:.2} Mpixel/s in the shading stage\n",
            "frame", self.frame_milliseconds, self.megapixels_per_second, self.shade_megapixels_per_second
        );
        out
    }
}
