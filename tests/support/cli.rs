//! The command line as the tests run it: the binary, its error output, and one rule for
//! how it fails: exit code 2 where clap refuses the command line as it parses it, 1 for
//! everything found wrong after, never a panic, and the file or option named.

use assert_cmd::Command;
use std::process::Output;

/// The `logsh` binary of this build.
pub fn logsh() -> Command {
    Command::cargo_bin("logsh").unwrap()
}

pub fn stderr_of(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Runs `logsh` with `args`, asserting success.
pub fn run(args: &[&str]) {
    let output = logsh().args(args).output().unwrap();
    assert!(output.status.success(), "logsh {args:?}: {}", stderr_of(&output));
}

/// Exit code of a command line clap refuses while parsing it.
pub const REFUSED_WHILE_PARSING: i32 = 2;
/// Exit code of anything found wrong after parsing: options out of range, bad files.
pub const FAILED: i32 = 1;

/// `output` failed with `code`, without a panic, and its error holds every one of
/// `needles`.
pub fn assert_fails_with(output: &Output, code: i32, needles: &[&str]) {
    let stderr = stderr_of(output);
    assert_eq!(output.status.code(), Some(code), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for needle in needles {
        assert!(stderr.contains(needle), "expected {needle:?} in: {stderr}");
    }
}
