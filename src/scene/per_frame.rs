//! What changes from frame to frame besides the G-buffers, cameras and blockers: the
//! lamps, the World's strength, rotation or colour, and the height field's rectangle
//! (`per_frame` in scene.json, a path with `#`).
//!
//! A scene whose light and terrain stay put has no `per_frame`, and reads as it always
//! did. Where something is keyed, each frame's file holds what that frame has:
//!
//! ```json
//! {
//!   "frame": 2,
//!   "lights": [{"type": "point", "position": [0.4, 0.0, 0.65], "radius": 0.1, "power": 150}],
//!   "light": {"strength": 0.8, "rotation": [0, 0, 35]},
//!   "heightfield": {"min": [-15.2, -15.0], "max": [15.1, 15.0]}
//! }
//! ```
//!
//! - `frame` must be the frame the file is read for (a file copied to the wrong number is
//!   refused).
//! - `lights` replaces scene.json's `lights` for the frame, entry for entry the same
//!   schema (an empty list: no lamp on that frame).
//! - `light` changes the World: `strength` and `rotation` of an `environment` light, or
//!   the colour of a `constant` one; its map file and anything else stay scene.json's.
//! - `heightfield` gives the frame's height map its own rectangle, when the terrain's
//!   extent moves with the frame (scene.json's `min` and `max` otherwise).
//!
//! Every key but `frame` is optional; the values are checked as scene.json's are.

use super::{
    colour, parse_lamp, read_json, Lamp, LightSpec, PointLight, SceneError, SharpLightFile, SunLight, MAX_SUNS,
};
use serde::Deserialize;
use std::path::Path;

/// One frame's file, as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PerFrameFile {
    frame: i64,
    lights: Option<Vec<SharpLightFile>>,
    light: Option<WorldChangeFile>,
    heightfield: Option<RectangleFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldChangeFile {
    strength: Option<f64>,
    rotation: Option<[f64; 3]>,
    constant: Option<[f64; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RectangleFile {
    min: [f64; 2],
    max: [f64; 2],
}

/// What one frame changes of scene.json; `None` keeps scene.json's.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameChanges {
    /// The frame's lamps (`lights`), suns and points apart.
    pub lamps: Option<(Vec<SunLight>, Vec<PointLight>)>,
    /// The World's light of the frame, scene.json's with `light` applied.
    pub light: Option<LightSpec>,
    /// The height map's rectangle, `(min, max)`.
    pub rectangle: Option<([f64; 2], [f64; 2])>,
}

impl FrameChanges {
    /// Reads `file`, the per-frame file of `frame`, against the scene's `light`.
    pub fn read(file: &Path, frame: i64, light: &LightSpec) -> Result<FrameChanges, SceneError> {
        let raw: PerFrameFile = read_json(file, "the frame's lights and terrain (per_frame)")?;
        if raw.frame != frame {
            return Err(SceneError::invalid(
                file,
                format!("\"frame\" is {}, but the file is frame {frame}'s", raw.frame),
            ));
        }
        let lamps = match raw.lights {
            None => None,
            Some(lights) => Some(parse_lamps(file, &lights)?),
        };
        let light = match raw.light {
            None => None,
            Some(change) => Some(changed_light(file, light, &change)?),
        };
        let rectangle = match raw.heightfield {
            None => None,
            Some(RectangleFile { min, max }) => {
                if min.iter().chain(&max).any(|v| !v.is_finite()) {
                    return Err(SceneError::NonFinite { file: file.to_path_buf(), what: "heightfield min/max".into() });
                }
                if !(min[0] < max[0] && min[1] < max[1]) {
                    return Err(SceneError::invalid(
                        file,
                        format!("heightfield: min {min:?} must be below max {max:?} in x and y"),
                    ));
                }
                Some((min, max))
            }
        };
        Ok(FrameChanges { lamps, light, rectangle })
    }
}

/// scene.json's (or a frame's) `lights`, suns and points apart.
pub(super) fn parse_lamps(
    file: &Path,
    lights: &[SharpLightFile],
) -> Result<(Vec<SunLight>, Vec<PointLight>), SceneError> {
    if lights.len() > MAX_SUNS {
        return Err(SceneError::invalid(file, format!("{} lights; at most {MAX_SUNS}", lights.len())));
    }
    let (mut suns, mut points) = (Vec::new(), Vec::new());
    for (i, l) in lights.iter().enumerate() {
        match parse_lamp(file, i, l)? {
            Lamp::Sun(sun) => suns.push(sun),
            Lamp::Point(point) => points.push(point),
        }
    }
    Ok((suns, points))
}

/// The scene's `light` with a frame's `light` applied.
fn changed_light(file: &Path, light: &LightSpec, change: &WorldChangeFile) -> Result<LightSpec, SceneError> {
    let refuse = |key: &str, kind: &str| {
        Err(SceneError::invalid(
            file,
            format!("light: \"{key}\" changes an environment light, but the scene's is {kind}"),
        ))
    };
    match light {
        LightSpec::Environment { path, strength, rotation } => {
            if change.constant.is_some() {
                return Err(SceneError::invalid(
                    file,
                    "light: \"constant\" changes a constant light, but the scene's is an environment map",
                ));
            }
            let strength = match change.strength {
                None => *strength,
                Some(s) if !s.is_finite() => {
                    return Err(SceneError::NonFinite { file: file.to_path_buf(), what: "light strength".into() })
                }
                Some(s) if !(0.0..=f64::from(f32::MAX)).contains(&s) => {
                    return Err(SceneError::invalid(file, format!("light: strength {s} must be >= 0")))
                }
                Some(s) => s as f32,
            };
            let rotation = match change.rotation {
                None => *rotation,
                Some(r) if r.iter().any(|v| !v.is_finite()) => {
                    return Err(SceneError::NonFinite { file: file.to_path_buf(), what: "light rotation".into() })
                }
                Some(r) => r,
            };
            Ok(LightSpec::Environment { path: path.clone(), strength, rotation })
        }
        LightSpec::Constant(c) => {
            if change.strength.is_some() {
                return refuse("strength", "a constant colour (give the frame's colour as \"constant\")");
            }
            if change.rotation.is_some() {
                return refuse("rotation", "a constant colour");
            }
            Ok(LightSpec::Constant(match change.constant {
                Some(v) => colour(file, "light constant", v)?,
                None => *c,
            }))
        }
        LightSpec::Sh(_) => Err(SceneError::invalid(file, "light: an \"sh\" light cannot change per frame")),
    }
}
