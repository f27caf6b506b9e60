//! How `logsh render` reports progress: a bar on a terminal, one line per frame in logs,
//! JSON lines for farm managers and scripts, or nothing.
//!
//! JSON lines go to standard output, one object per line: `{"event": "start", "frames":
//! N}`, then per frame `{"event": "frame", "frame": F, "index": I, "total": N, "status":
//! "rendered" | "skipped" | "failed", "seconds": S, "outputs": [...], "error": "..."}`
//! (`error` only when failed), and last `{"event": "done", "rendered": R, "skipped": K,
//! "failed": [F, ...]}`. Everything else goes to standard error, notices included (a
//! frame shaded on the CPU by the fall-back of `--device auto`), in every mode.

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

/// Receives the events of a sequence, in order, from one thread.
pub trait Progress: Send {
    fn start(&mut self, total: usize);
    fn frame_started(&mut self, frame: i64, index: usize);
    fn frame_finished(&mut self, outcome: &FrameOutcome, index: usize, total: usize);
    /// Something the user should know about how a frame was shaded.
    fn notice(&mut self, message: &str);
    fn finish(&mut self, outcomes: &[FrameOutcome]);
}

/// The reporter for `mode`.
pub fn reporter(mode: ProgressMode) -> Box<dyn Progress> {
    match mode {
        ProgressMode::Auto | ProgressMode::Bar if std::io::stderr().is_terminal() => Box::new(Bar::default()),
        ProgressMode::Auto | ProgressMode::Bar | ProgressMode::Lines => Box::new(Lines),
        ProgressMode::Json => Box::new(Json),
        ProgressMode::None => Box::new(Silent),
    }
}

fn describe(outcome: &FrameOutcome) -> String {
    match &outcome.status {
        FrameStatus::Rendered { seconds, outputs } => {
            format!(
                "rendered in {seconds:.2} s: {}",
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
    }
}

struct Lines;

impl Progress for Lines {
    fn start(&mut self, total: usize) {
        eprintln!("rendering {total} frame(s)");
    }
    fn frame_started(&mut self, _: i64, _: usize) {}
    fn frame_finished(&mut self, outcome: &FrameOutcome, index: usize, total: usize) {
        eprintln!("frame {} ({}/{total}) {}", outcome.frame, index + 1, describe(outcome));
    }
    fn notice(&mut self, message: &str) {
        eprintln!("{message}");
    }
    fn finish(&mut self, _: &[FrameOutcome]) {}
}

#[derive(Default)]
struct Bar {
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
            if let FrameStatus::Failed { .. } = outcome.status {
                bar.println(format!("frame {} {}", outcome.frame, describe(outcome)));
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

struct Json;

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
        match &outcome.status {
            FrameStatus::Rendered { seconds, outputs } => {
                event["status"] = json!("rendered");
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
        }
        emit(event);
    }
    fn notice(&mut self, message: &str) {
        eprintln!("{message}");
    }
    fn finish(&mut self, outcomes: &[FrameOutcome]) {
        let count = |f: fn(&FrameStatus) -> bool| outcomes.iter().filter(|o| f(&o.status)).count();
        let failed: Vec<i64> =
            outcomes.iter().filter(|o| matches!(o.status, FrameStatus::Failed { .. })).map(|o| o.frame).collect();
        emit(json!({
            "event": "done",
            "rendered": count(|s| matches!(s, FrameStatus::Rendered { .. })),
            "skipped": count(|s| matches!(s, FrameStatus::Skipped { .. })),
            "failed": failed,
        }));
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
