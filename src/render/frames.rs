//! Frame specifications as render farm managers and oiiotool write them.
//!
//! A spec is a comma-separated list of items, each one of
//! - `N`: one frame (`7`, `-3`);
//! - `A-B` or `A..B`: every frame from `A` to `B` inclusive, counting down when `A > B`
//!   (oiiotool's `10-1`);
//! - `A-BxS` or `A-B:S` (also after `A..B`): every `S`-th frame from `A` (Deadline and
//!   oiiotool write `x`, Houdini and some farm managers `:`).
//!
//! Frames keep the order given; a frame listed twice is rendered once, where it first
//! appears. Negative frame numbers are allowed (`-5--1` is -5 to -1). Whitespace around
//! items is ignored.

use std::fmt;
use std::str::FromStr;

/// Most frames one spec may name: a typo like `1-1000000000` is refused instead of
/// allocating a list of a billion frames.
pub const MAX_FRAMES: usize = 1_000_000;

/// A parsed frame specification: the frames in render order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameSpec {
    pub text: String,
    pub frames: Vec<i64>,
}

/// Why a frame specification was refused; the message quotes the offending item.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("frame spec \"{spec}\": {message}")]
pub struct FrameSpecError {
    pub spec: String,
    pub message: String,
}

impl fmt::Display for FrameSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// Splits `A-B` (either number may be negative) or `A..B` into its two ends.
fn split_range(item: &str) -> Option<(&str, &str)> {
    if let Some((a, b)) = item.split_once("..") {
        return Some((a, b));
    }
    // The separating `-` is the first one after at least one digit of the start.
    let start_digits = item.strip_prefix('-').unwrap_or(item);
    let offset = item.len() - start_digits.len();
    let first_digit_end = start_digits.find(|c: char| !c.is_ascii_digit())?;
    let at = offset + first_digit_end;
    (item[at..].starts_with('-')).then(|| (&item[..at], &item[at + 1..]))
}

impl FromStr for FrameSpec {
    type Err = FrameSpecError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let fail = |message: String| FrameSpecError { spec: text.to_string(), message };
        let number = |item: &str, s: &str| {
            s.trim()
                .parse::<i64>()
                .map_err(|_| fail(format!("\"{item}\" is not a frame, a range A-B or A..B, or a stepped range A-BxS")))
        };
        let mut frames = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for item in text.split(',') {
            let item = item.trim();
            if item.is_empty() {
                return Err(fail("empty item (two commas in a row, or a comma at an end)".into()));
            }
            let (range, step) = match item.split_once(['x', ':']) {
                Some((range, step)) => (range, Some(number(item, step)?)),
                None => (item, None),
            };
            let (start, end) = match split_range(range) {
                Some((a, b)) => (number(item, a)?, number(item, b)?),
                None if step.is_none() => {
                    let frame = number(item, range)?;
                    (frame, frame)
                }
                None => return Err(fail(format!("\"{item}\": a step needs a range before it (A-BxS)"))),
            };
            let step = step.unwrap_or(1);
            if step <= 0 {
                return Err(fail(format!("\"{item}\": the step must be at least 1")));
            }
            let count = (i128::from(end) - i128::from(start)).unsigned_abs() / step as u128 + 1;
            if count + frames.len() as u128 > MAX_FRAMES as u128 {
                return Err(fail(format!("more than {MAX_FRAMES} frames")));
            }
            let direction: i128 = if end >= start { 1 } else { -1 };
            for k in 0..count as i128 {
                // Lies between start and end, so it fits in i64 even where k * step alone would not.
                let frame = (i128::from(start) + direction * k * i128::from(step)) as i64;
                if seen.insert(frame) {
                    frames.push(frame);
                }
            }
        }
        Ok(FrameSpec { text: text.to_string(), frames })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(s: &str) -> Vec<i64> {
        s.parse::<FrameSpec>().unwrap_or_else(|e| panic!("{e}")).frames
    }

    #[test]
    fn farm_and_oiiotool_forms() {
        assert_eq!(frames("1-5"), vec![1, 2, 3, 4, 5]);
        assert_eq!(frames("1-10x3"), vec![1, 4, 7, 10]);
        assert_eq!(frames("1-10:4"), vec![1, 5, 9]);
        assert_eq!(frames("1,5,10-12"), vec![1, 5, 10, 11, 12]);
        assert_eq!(frames("1..4"), vec![1, 2, 3, 4]);
        assert_eq!(frames("1..9x4"), vec![1, 5, 9]);
        assert_eq!(frames("5-3"), vec![5, 4, 3]);
        assert_eq!(frames("7"), vec![7]);
        assert_eq!(frames(" 3 , 1-2 "), vec![3, 1, 2]);
        assert_eq!(frames("-2-1"), vec![-2, -1, 0, 1]);
        assert_eq!(frames("-5--3"), vec![-5, -4, -3]);
        assert_eq!(frames("-3..-1"), vec![-3, -2, -1]);
        assert_eq!(frames("1-3,2-4"), vec![1, 2, 3, 4]);
        // Ends near the limits of i64: the step arithmetic must not overflow.
        let far = frames("-9000000000000000000-9000000000000000000x100000000000000");
        assert_eq!(
            (far.len(), far[0], far[far.len() - 1]),
            (180_001, -9_000_000_000_000_000_000, 9_000_000_000_000_000_000)
        );
    }

    #[test]
    fn malformed_specs_are_refused_with_the_item() {
        for (bad, needle) in [
            ("", "empty item"),
            ("1,,2", "empty item"),
            ("1-", "\"1-\""),
            ("a-b", "\"a-b\""),
            ("1-10x0", "step must be at least 1"),
            ("1-10x-2", "step must be at least 1"),
            ("5x2", "needs a range"),
            ("1-2-3", "\"1-2-3\""),
            ("1-99999999999", "more than"),
            ("-9223372036854775808-9223372036854775807", "more than"),
            ("99999999999999999999", "is not a frame"),
            ("-9000000000000000000-9000000000000000000x1000000000000", "more than"),
        ] {
            let Err(err) = bad.parse::<FrameSpec>() else { panic!("{bad:?} was accepted") };
            let err = err.to_string();
            assert!(err.contains(needle), "{bad:?}: {err}");
        }
    }
}
