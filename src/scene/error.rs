//! The one error type of scene reading: every variant names the file and says what is
//! wrong in words a user can act on.

use std::fmt;
use std::path::{Path, PathBuf};

/// Largest accepted image side, in pixels.
pub const MAX_IMAGE_SIDE: usize = 16384;
/// Largest accepted pixel count of one image (2^28, one gigabyte per f32 channel).
pub const MAX_IMAGE_PIXELS: usize = 1 << 28;

/// Why a scene, a frame or one of its files could not be read.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file named by `scene.json` (or `scene.json` itself) does not exist.
    #[error("{}: file not found ({what})", .file.display())]
    MissingFile { file: PathBuf, what: String },

    /// A scene was asked for at a path that is a file, not a scene directory.
    #[error("{}: {what}", .path.display())]
    NotASceneDirectory { path: PathBuf, what: String },

    /// The operating system refused to read a file.
    #[error("{}: cannot read: {cause}", .file.display())]
    Io { file: PathBuf, cause: std::io::Error },

    /// A JSON file is malformed, has an unknown key or a value of the wrong type.
    #[error("{}:{line}:{column}: {message}", .file.display())]
    Json { file: PathBuf, line: usize, column: usize, message: String },

    /// `scene.json` declares a format version this reader does not know.
    #[error("{}: unsupported scene format version {found} (this logsh reads version 1)", .file.display())]
    Version { file: PathBuf, found: String },

    /// The EXR (or HDR) decoder rejected a file.
    #[error("{}: not a readable image: {message}", .file.display())]
    Image { file: PathBuf, message: String },

    /// A channel the reader needs is not in an EXR file.
    #[error("{}: missing channel \"{channel}\" (found: {})", .file.display(), found_list(.found))]
    MissingChannel { file: PathBuf, channel: String, found: Vec<String> },

    /// An image is larger than the reader accepts; checked before any pixel is allocated.
    #[error(
        "{}: image of {width} x {height} pixels is too large (at most {MAX_IMAGE_SIDE} pixels a side and {MAX_IMAGE_PIXELS} pixels in all)",
        .file.display()
    )]
    TooLarge { file: PathBuf, width: usize, height: usize },

    /// Two buffers of one frame (or two channels of one file) differ in size.
    #[error(
        "{}: size {}x{} does not match {}x{} of {}",
        .file.display(), .found[0], .found[1], .expected[0], .expected[1], .reference.display()
    )]
    SizeMismatch { file: PathBuf, found: [usize; 2], expected: [usize; 2], reference: PathBuf },

    /// A material index in a G-buffer is fractional, negative or not in the table.
    #[error("{}: pixel ({x}, {y}): material index {value} {reason}", .file.display())]
    MaterialIndex { file: PathBuf, x: usize, y: usize, value: f32, reason: String },

    /// A value (JSON number, pixel, sample) is NaN or infinite where a number is needed.
    #[error("{}: {what} is not a finite number", .file.display())]
    NonFinite { file: PathBuf, what: String },

    /// A frame that is not one of the scene's `frames` was asked for.
    #[error("{}: frame {frame} is not one of the scene's frames ({frames})", .file.display())]
    FrameOutOfRange { file: PathBuf, frame: i64, frames: String },

    /// An output path would overwrite one of the scene's inputs.
    #[error("{}: refusing to write over an input of the scene ({what})", .file.display())]
    OutputIsInput { file: PathBuf, what: String },

    /// Any other violation of the format, stated in words.
    #[error("{}: {message}", .file.display())]
    Invalid { file: PathBuf, message: String },
}

fn found_list(found: &[String]) -> String {
    if found.is_empty() {
        return "no channels".to_string();
    }
    let quoted: Vec<String> = found.iter().map(|n| format!("\"{n}\"")).collect();
    quoted.join(", ")
}

impl SceneError {
    pub(crate) fn invalid(file: &Path, message: impl fmt::Display) -> Self {
        Self::Invalid { file: file.to_path_buf(), message: message.to_string() }
    }

    /// Wraps an I/O error, turning "not found" into [`SceneError::MissingFile`].
    pub(crate) fn io(file: &Path, what: &str, source: std::io::Error) -> Self {
        if source.kind() == std::io::ErrorKind::NotFound {
            Self::MissingFile { file: file.to_path_buf(), what: what.to_string() }
        } else {
            Self::Io { file: file.to_path_buf(), cause: source }
        }
    }

    /// Wraps a serde_json error with its line and column; the message loses serde's own
    /// " at line L column C" suffix since the position leads the message.
    pub(crate) fn json(file: &Path, err: serde_json::Error) -> Self {
        let text = err.to_string();
        let message = match text.rfind(" at line ") {
            Some(i) => text[..i].to_string(),
            None => text,
        };
        Self::Json { file: file.to_path_buf(), line: err.line(), column: err.column(), message }
    }

    /// The file the error is about.
    pub fn file(&self) -> &Path {
        match self {
            Self::MissingFile { file, .. }
            | Self::Io { file, .. }
            | Self::NotASceneDirectory { path: file, .. }
            | Self::Json { file, .. }
            | Self::Version { file, .. }
            | Self::Image { file, .. }
            | Self::MissingChannel { file, .. }
            | Self::TooLarge { file, .. }
            | Self::SizeMismatch { file, .. }
            | Self::MaterialIndex { file, .. }
            | Self::NonFinite { file, .. }
            | Self::FrameOutOfRange { file, .. }
            | Self::OutputIsInput { file, .. }
            | Self::Invalid { file, .. } => file,
        }
    }
}

/// Refuses image sizes over the limits, before anything is allocated.
pub(crate) fn check_image_size(file: &Path, width: usize, height: usize) -> Result<(), SceneError> {
    if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE || width.saturating_mul(height) > MAX_IMAGE_PIXELS {
        return Err(SceneError::TooLarge { file: file.to_path_buf(), width, height });
    }
    if width == 0 || height == 0 {
        return Err(SceneError::invalid(file, format!("image of {width} x {height} pixels is empty")));
    }
    Ok(())
}

/// Wraps an error of the `exr` crate. A file that ends early (the usual damage: a copy or
/// a write cut short) says so, since the decoder's own words for it are cryptic.
pub(crate) fn exr_error(file: &Path, what: &str, e: exr::error::Error) -> SceneError {
    let truncated = |detail: &str| SceneError::Image {
        file: file.to_path_buf(),
        message: format!("the file ends early or is damaged ({detail}); write or copy it again"),
    };
    match e {
        exr::error::Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => truncated(&io.to_string()),
        exr::error::Error::Io(io) => SceneError::io(file, what, io),
        exr::error::Error::Invalid(why) if why.contains("missing bytes") => truncated(&why),
        exr::error::Error::Invalid(why) if why.contains("file identifier missing") => SceneError::Image {
            file: file.to_path_buf(),
            message: "not an OpenEXR file (it does not begin as one)".to_string(),
        },
        other => SceneError::Image { file: file.to_path_buf(), message: other.to_string() },
    }
}
