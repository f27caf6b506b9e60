//! Paths of `scene.json` stay inside the scene directory: a scene copied to a farm, or
//! downloaded, must not read (or make logsh refuse to write) files elsewhere.
//!
//! The check is lexical, on the path as written: a relative path whose `..` components
//! climb above the scene directory is refused, and so is an absolute path (or a Windows
//! drive or UNC path) unless it names a place inside the scene directory. Both `/` and
//! `\` count as separators so that a scene written on Windows is judged the same way.
//! Symbolic links inside the directory are followed as the system does (a studio may
//! link a shared sky map into each shot).

use super::error::SceneError;
use std::path::{Component, Path};

/// Refuses `path` (the value of key `key` in `file`) when it leads outside `dir`.
pub(crate) fn check_inside(file: &Path, dir: &Path, key: &str, path: &str) -> Result<(), SceneError> {
    let refuse = |why: &str| {
        SceneError::invalid(
            file,
            format!("\"{key}\": path \"{path}\" {why}; paths must lie inside the scene directory"),
        )
    };
    if path.is_empty() {
        return Err(SceneError::invalid(file, format!("\"{key}\": the path is empty")));
    }
    if path.contains('\0') {
        return Err(refuse("holds a NUL character"));
    }
    let windows_absolute = path.starts_with('\\') || path.as_bytes().get(1) == Some(&b':');
    if Path::new(path).is_absolute() || windows_absolute {
        let inside = !windows_absolute && {
            let scene_dir = absolute_lexical(dir);
            let target = absolute_lexical(Path::new(path));
            target.starts_with(&scene_dir) && target != scene_dir
        };
        return if inside { Ok(()) } else { Err(refuse("is absolute and outside the scene directory")) };
    }
    let mut depth: i64 = 0;
    for part in path.split(['/', '\\']) {
        match part {
            "" | "." => {}
            ".." => {
                depth -= 1;
                if depth < 0 {
                    return Err(refuse("climbs out of the scene directory with \"..\""));
                }
            }
            _ => depth += 1,
        }
    }
    if depth == 0 {
        return Err(refuse("names the scene directory itself, not a file"));
    }
    Ok(())
}

/// `path` made absolute against the working directory, `.` and `..` resolved lexically.
fn absolute_lexical(path: &Path) -> std::path::PathBuf {
    let abs =
        if path.is_absolute() { path.to_path_buf() } else { std::env::current_dir().unwrap_or_default().join(path) };
    let mut clean = std::path::PathBuf::new();
    for c in abs.components() {
        match c {
            Component::ParentDir => {
                clean.pop();
            }
            Component::CurDir => {}
            other => clean.push(other),
        }
    }
    clean
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(dir: &str, path: &str) -> bool {
        check_inside(Path::new("scene.json"), Path::new(dir), "gbuffer", path).is_ok()
    }

    #[test]
    fn paths_stay_inside() {
        assert!(ok("/shots/a", "gbuffer.####.exr"));
        assert!(ok("/shots/a", "passes/../gbuffer.exr"));
        assert!(ok("/shots/a", "/shots/a/sky.exr"));
        assert!(!ok("/shots/a", "../b/gbuffer.exr"));
        assert!(!ok("/shots/a", "passes/../../b.exr"));
        assert!(!ok("/shots/a", "..\\b.exr"));
        assert!(!ok("/shots/a", "/etc/passwd"));
        assert!(!ok("/shots/a", "/shots/ab/sky.exr"));
        assert!(!ok("/shots/a", "C:\\sky.exr"));
        assert!(!ok("/shots/a", "\\\\server\\sky.exr"));
        assert!(!ok("/shots/a", ""));
        assert!(!ok("/shots/a", "."));
    }
}
