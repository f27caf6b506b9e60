//! How `logsh render` and `logsh relight` report progress: a bar on a terminal, one line
//! per frame in logs, JSON lines for farm managers and scripts, or nothing.
//!
//! JSON lines go to standard output, one object per line: `{"event": "start", "frames":
//! N}`, then per frame `{"event": "frame", "frame": F, "index": I, "total": N, "status":
//! "rendered" | "skipped" | "failed", "seconds": S, "outputs": [...], "error": "..."}`
//! (`error` only when failed), and last `{"event": "done", "rendered": R, "skipped": K,
//! "failed": [F, ...]}`. A relight's frame events add `"input"` (the frame's file; `frame`
//! is the number its header records, `null` where it does not read), its statuses are
//! `"relit"`, `"failed"` and `"stopped"` (not relit: a frame before it failed, which stops
//! a relight), and its last event is `{"event": "done", "relit": R, "failed": [FILE],
//! "stopped": [FILE, ...]}`. Everything else goes to standard error, notices included (a
//! frame shaded on the CPU by the fall-back of `--device auto`, a relight's warnings), in
//! every mode.

use super::{FrameOutcome, FrameStatus};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::json;
use std::io::{IsTerminal, Write};

/// The `--progress` choices.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum ProgressMode {
    /// A bar when standard error is a terminal, lines otherwise.
    Auto,
    /// An indicatif bar on standard error; lines where standard error is not a terminal,
    /// since no bar can be drawn there.
    Bar,
    /// One plain line per frame on standard error.
    Lines,
    /// One JSON object per event on standard output.
    Json,
    /// Nothing but errors and the final summary.
    None,
}

/// The command whose frames are reported, which words the reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    Render,
    Relight,
}

impl Command {
    /// What it does to a frame, as under way.
    fn doing(self) -> &'static str {
        match self {
            Command::Render => "rendering",
            Command::Relight => "relighting",
        }
    }

    /// What it has done to a frame: the status of a frame done.
    fn done(self) -> &'static str {
        match self {
            Command::Render => "rendered",
            Command::Relight => "relit",
        }
    }
}

/// Receives the events of a sequence, in order, from one thread.
pub trait Progress: Send {
    fn start(&mut self, total: usize);
    fn frame_started(&mut self, frame: i64, index: usize);
    fn frame_finished(&mut self, outcome: &FrameOutcome, index: usize, total: usize);
    /// Something the user should know about how a frame was shaded.
    fn notice(&mut self, message: &str);
    fn finish(&mut self, outcomes: &[FrameOutcome]);
}

/// The reporter for `mode`, wording the frames of `command`.
pub fn reporter(mode: ProgressMode, command: Command) -> Box<dyn Progress> {
    match mode {
        ProgressMode::Auto | ProgressMode::Bar if std::io::stderr().is_terminal() => {
            Box::new(Bar { command, bar: None })
        }
        ProgressMode::Auto | ProgressMode::Bar | ProgressMode::Lines => Box::new(Lines(command)),
        ProgressMode::Json => Box::new(Json(command)),
        ProgressMode::None => Box::new(Silent),
    }
}

fn describe(outcome: &FrameOutcome, command: Command) -> String {
    match &outcome.status {
        FrameStatus::Done { seconds, outputs } => {
            format!(
                "{} in {seconds:.2} s: {}",
                command.done(),
                outputs.first().map(|p| p.display().to_string()).unwrap_or_default()
            )
        }
        FrameStatus::Skipped { outputs } => {
            format!(
                "skipped, already rendered: {}",
                outputs.first().map(|p| p.display().to_string()).unwrap_or_default()
            )
        }
        FrameStatus::Failed { error } => format!("FAILED: {error}"),
        FrameStatus::Stopped => format!("not {}: a frame before it failed", command.done()),
    }
}

struct Lines(Command);

impl Progress for Lines {
    fn start(&mut self, total: usize) {
        eprintln!("{} {total} frame(s)", self.0.doing());
    }
    fn frame_started(&mut self, _: i64, _: usize) {}
    fn frame_finished(&mut self, outcome: &FrameOutcome, index: usize, total: usize) {
        eprintln!("{} ({}/{total}) {}", outcome.label(), index + 1, describe(outcome, self.0));
    }
    fn notice(&mut self, message: &str) {
        eprintln!("{message}");
    }
    fn finish(&mut self, _: &[FrameOutcome]) {}
}

struct Bar {
    command: Command,
    bar: Option<ProgressBar>,
}

impl Progress for Bar {
    fn start(&mut self, total: usize) {
        let bar = ProgressBar::with_draw_target(Some(total as u64), ProgressDrawTarget::stderr());
        bar.set_style(
            ProgressStyle::with_template("{msg:20} [{bar:40}] {pos}/{len} frames {elapsed}<{eta}")
                .expect("valid template"),
        );
        self.bar = Some(bar);
    }
    fn frame_started(&mut self, frame: i64, _: usize) {
        if let Some(bar) = &self.bar {
            bar.set_message(format!("frame {frame}"));
        }
    }
    fn frame_finished(&mut self, outcome: &FrameOutcome, _: usize, _: usize) {
        if let Some(bar) = &self.bar {
            if let FrameStatus::Failed { .. } | FrameStatus::Stopped = outcome.status {
                bar.println(format!("{} {}", outcome.label(), describe(outcome, self.command)));
            }
            bar.inc(1);
        }
    }
    fn notice(&mut self, message: &str) {
        match &self.bar {
            Some(bar) => bar.println(message),
            None => eprintln!("{message}"),
        }
    }
    fn finish(&mut self, _: &[FrameOutcome]) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}

struct Json(Command);

fn emit(value: serde_json::Value) {
    let mut out = std::io::stdout().lock();
    // A closed pipe must not stop the render; the frames on disk are what counts.
    let _ = writeln!(out, "{value}");
    let _ = out.flush();
}

impl Progress for Json {
    fn start(&mut self, total: usize) {
        emit(json!({"event": "start", "frames": total}));
    }
    fn frame_started(&mut self, _: i64, _: usize) {}
    fn frame_finished(&mut self, outcome: &FrameOutcome, index: usize, total: usize) {
        let mut event = json!({"event": "frame", "frame": outcome.frame, "index": index, "total": total});
        if let Some(input) = &outcome.input {
            event["input"] = json!(input);
        }
        match &outcome.status {
            FrameStatus::Done { seconds, outputs } => {
                event["status"] = json!(self.0.done());
                event["seconds"] = json!(seconds);
                event["outputs"] = json!(outputs);
            }
            FrameStatus::Skipped { outputs } => {
                event["status"] = json!("skipped");
                event["outputs"] = json!(outputs);
            }
            FrameStatus::Failed { error } => {
                event["status"] = json!("failed");
                event["error"] = json!(error);
            }
            FrameStatus::Stopped => event["status"] = json!("stopped"),
        }
        emit(event);
    }
    fn notice(&mut self, message: &str) {
        eprintln!("{message}");
    }
    fn finish(&mut self, outcomes: &[FrameOutcome]) {
        let count = |f: fn(&FrameStatus) -> bool| outcomes.iter().filter(|o| f(&o.status)).count();
        // A render's frames by number, a relight's by file.
        let named = |f: fn(&FrameStatus) -> bool| -> Vec<serde_json::Value> {
            outcomes
                .iter()
                .filter(|o| f(&o.status))
                .map(|o| o.input.as_ref().map_or_else(|| json!(o.frame), |input| json!(input)))
                .collect()
        };
        let failed = named(|s| matches!(s, FrameStatus::Failed { .. }));
        let done = count(|s| matches!(s, FrameStatus::Done { .. }));
        emit(match self.0 {
            Command::Render => json!({
                "event": "done",
                "rendered": done,
                "skipped": count(|s| matches!(s, FrameStatus::Skipped { .. })),
                "failed": failed,
            }),
            Command::Relight => json!({
                "event": "done",
                "relit": done,
                "failed": failed,
                "stopped": named(|s| matches!(s, FrameStatus::Stopped)),
            }),
        });
    }
}

struct Silent;

impl Progress for Silent {
    fn start(&mut self, _: usize) {}
    fn frame_started(&mut self, _: i64, _: usize) {}
    fn frame_finished(&mut self, _: &FrameOutcome, _: usize, _: usize) {}
    fn notice(&mut self, message: &str) {
        eprintln!("{message}");
    }
    fn finish(&mut self, _: &[FrameOutcome]) {}
}
