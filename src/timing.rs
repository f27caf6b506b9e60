//! Per-stage times of one shaded frame, as either executor measures them.

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
    /// Where the frame was shaded (`executor::Executor::describe`); under
    /// `--device auto` a frame the adapter refuses is shaded on the CPU.
    pub device: String,
    /// Whether that was a GPU (whose program can be specialised, `bench --specialise`).
    pub on_gpu: bool,
    /// Of a supersampled frame shaded adaptively: the samples shaded, and the frame's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples: Option<(usize, usize)>,
}

impl StageTimings {
    pub fn add(&mut self, name: &'static str, milliseconds: f64, clock: Clock) {
        match self.stages.iter_mut().find(|s| s.name == name) {
            Some(stage) => stage.milliseconds += milliseconds,
            None => self.stages.push(Stage { name, milliseconds, clock }),
        }
    }

    /// Adds each stage of `other` to its namesake here, or after the others.
    pub fn add_all(&mut self, other: &StageTimings) {
        for stage in &other.stages {
            self.add(stage.name, stage.milliseconds, stage.clock);
        }
    }

    /// Adds the wall time since `since` to stage `name`.
    pub fn add_wall(&mut self, name: &'static str, since: Instant) {
        self.add(name, since.elapsed().as_secs_f64() * 1e3, Clock::Wall);
    }
}
