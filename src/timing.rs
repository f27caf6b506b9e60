//! Per-stage times of one shaded frame, as `logsh bench` reports them.

use std::time::Instant;

/// Where a stage's time was measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Clock {
    /// GPU timestamp queries: the time the GPU spent in the pass.
    Gpu,
    /// Host wall time.
    Wall,
}

/// One timed stage of a frame.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Stage {
    pub name: &'static str,
    pub milliseconds: f64,
    pub clock: Clock,
}

/// Per-stage times of one frame, in the order the stages first ran; a stage that runs
/// once per tile accumulates.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct StageTimings {
    pub stages: Vec<Stage>,
    /// Where the frame was shaded ([`crate::gpu::Executor::describe`]); under
    /// `--device auto` a frame the adapter refuses is shaded on the CPU.
    pub device: String,
}

impl StageTimings {
    pub fn add(&mut self, name: &'static str, milliseconds: f64, clock: Clock) {
        match self.stages.iter_mut().find(|s| s.name == name) {
            Some(stage) => stage.milliseconds += milliseconds,
            None => self.stages.push(Stage { name, milliseconds, clock }),
        }
    }

    /// Adds the wall time since `since` to stage `name`.
    pub fn add_wall(&mut self, name: &'static str, since: Instant) {
        self.add(name, since.elapsed().as_secs_f64() * 1e3, Clock::Wall);
    }

    pub fn total_milliseconds(&self) -> f64 {
        self.stages.iter().map(|s| s.milliseconds).sum()
    }
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
    pub specialisation: crate::gpu::Specialisation,
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
        gbuffer: &crate::scene::GBuffer,
        frame: i64,
        settings: &crate::shade::ShadingSettings,
        specialisation: crate::gpu::Specialisation,
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
            specialisation,
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
            "{}x{} frame {}, order {}, exp {}, W {}, {} program, on {}\nmedian of {} run(s)\n\n{:<20} {:>12}  clock\n",
            self.width,
            self.height,
            self.frame,
            self.order,
            self.exp,
            self.directions,
            match self.specialisation {
                crate::gpu::Specialisation::Full => "fully specialised",
                crate::gpu::Specialisation::Order => "order-specialised",
                crate::gpu::Specialisation::None => "unspecialised",
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
