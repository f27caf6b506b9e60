//! Per-frame camera and sphere blockers (`camera.####.json`, `blockers.####.json`).
//!
//! Camera conventions are Blender's: the camera looks down its local -Z, local +Y is up,
//! local +X is right; `matrix_world` is the object's 4x4 world matrix written row by row
//! (translation in the last column). The sensor fit is Blender's default, "Auto": the
//! sensor width spans the larger image side, so `tan(fov / 2) = sensor_width_mm /
//! (2 lens_mm)` horizontally for a landscape frame and vertically for a portrait one. The
//! camera is used for view directions (Phong, water, background), not for positions,
//! which come from the G-buffer.

use super::error::SceneError;
use super::read_json;
use super::sun_shadow::{read_sun_shadows, SunShadowEntry, SunShadowMap};
use crate::vector::{cross, normalize, sub};
use serde::Deserialize;
use std::path::Path;
use std::sync::Arc;

/// A sphere blocker: something that casts a shadow.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sphere {
    pub center: [f64; 3],
    /// `>= 0`; 0 is a degenerate sphere that blocks nothing.
    pub radius: f64,
    /// The object the sphere approximates, as the G-buffer's object index names it;
    /// 0 (the default) for none. A receiver does not take shadow from the spheres of its
    /// own object that hold it ([`crate::logsh::view_blocker`]).
    #[serde(default)]
    pub object: u32,
}

impl Sphere {
    /// A sphere of no particular object.
    pub fn new(center: [f64; 3], radius: f64) -> Self {
        Self { center, radius, object: 0 }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BlockersFile {
    frame: Option<i64>,
    spheres: Vec<Sphere>,
    #[serde(default)]
    sun_shadows: Vec<SunShadowEntry>,
}

/// What casts shadows in one frame: the sphere proxies, and the suns' shadow maps of the
/// meshes themselves ([`super::sun_shadow`]).
#[derive(Clone, Debug, Default)]
pub struct FrameBlockers {
    pub spheres: Vec<Sphere>,
    pub sun_shadows: Vec<Arc<SunShadowMap>>,
}

/// Most blocker spheres a frame may hold: the tree of a million spheres
/// ([`crate::shade::blocker_tree`]) takes about 100 MB, the most one GPU storage binding
/// is guaranteed to hold (WebGPU's default 128 MiB).
pub const MAX_BLOCKERS: usize = 1_000_000;

/// Reads `blockers.####.json`: `frame` (optional; when present must equal `frame`),
/// `spheres` and, optionally, `sun_shadows` (images relative to `dir`). A negative radius
/// or a non-finite number is an error naming the sphere.
pub fn read_blockers(file: &Path, frame: i64, dir: &Path) -> Result<FrameBlockers, SceneError> {
    let raw: BlockersFile = read_json(file, "the sphere blockers")?;
    check_frame_key(file, raw.frame, frame)?;
    let most = MAX_BLOCKERS;
    if raw.spheres.len() > most {
        return Err(SceneError::invalid(
            file,
            format!(
                "{} spheres is more than the {most} a frame may hold; merge small blockers into larger spheres",
                raw.spheres.len()
            ),
        ));
    }
    for (i, s) in raw.spheres.iter().enumerate() {
        if s.center.iter().any(|v| !v.is_finite()) {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: format!("centre of sphere {i}") });
        }
        if !s.radius.is_finite() {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: format!("radius of sphere {i}") });
        }
        if s.radius < 0.0 {
            return Err(SceneError::invalid(file, format!("sphere {i} has negative radius {}", s.radius)));
        }
    }
    let sun_shadows = read_sun_shadows(&raw.sun_shadows, file, dir)?.into_iter().map(Arc::new).collect();
    Ok(FrameBlockers { spheres: raw.spheres, sun_shadows })
}

fn check_frame_key(file: &Path, found: Option<i64>, frame: i64) -> Result<(), SceneError> {
    match found {
        Some(f) if f != frame => {
            Err(SceneError::invalid(file, format!("says frame {f} but was read for frame {frame}")))
        }
        _ => Ok(()),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    frame: Option<i64>,
    position: [f64; 3],
    matrix_world: [[f64; 4]; 4],
    lens_mm: f64,
    sensor_width_mm: f64,
    resolution: [u32; 2],
}

/// A pinhole camera of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub position: [f64; 3],
    /// Rows of the world matrix.
    pub matrix_world: [[f64; 4]; 4],
    pub lens_mm: f64,
    pub sensor_width_mm: f64,
    /// Image width and height in pixels.
    pub resolution: [u32; 2],
}

impl Camera {
    /// Reads `camera.####.json`; `frame`, when present in the file, must equal `frame`.
    pub fn read(file: &Path, frame: i64) -> Result<Camera, SceneError> {
        let raw: CameraFile = read_json(file, "the camera")?;
        check_frame_key(file, raw.frame, frame)?;
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&raw.position) {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: "camera position".into() });
        }
        if !raw.matrix_world.iter().all(|r| finite(r)) {
            return Err(SceneError::NonFinite { file: file.to_path_buf(), what: "camera matrix_world".into() });
        }
        for (name, v) in [("lens_mm", raw.lens_mm), ("sensor_width_mm", raw.sensor_width_mm)] {
            if !v.is_finite() {
                return Err(SceneError::NonFinite { file: file.to_path_buf(), what: format!("camera {name}") });
            }
            if v <= 0.0 {
                return Err(SceneError::invalid(file, format!("camera {name} {v} must be > 0")));
            }
        }
        if raw.resolution[0] == 0 || raw.resolution[1] == 0 {
            return Err(SceneError::invalid(file, format!("camera resolution {:?} is empty", raw.resolution)));
        }
        Ok(Camera {
            position: raw.position,
            matrix_world: raw.matrix_world,
            lens_mm: raw.lens_mm,
            sensor_width_mm: raw.sensor_width_mm,
            resolution: raw.resolution,
        })
    }

    /// A camera at `position` looking at `target`, with `up` (world) roughly up in the
    /// image. `matrix_world` columns are right, up and backward (-forward).
    pub fn look_at(
        position: [f64; 3],
        target: [f64; 3],
        up: [f64; 3],
        lens_mm: f64,
        sensor_width_mm: f64,
        resolution: [u32; 2],
    ) -> Camera {
        let f = normalize(sub(target, position));
        let r = normalize(cross(f, up));
        let u = cross(r, f);
        let p = position;
        Camera {
            position,
            matrix_world: [
                [r[0], u[0], -f[0], p[0]],
                [r[1], u[1], -f[1], p[1]],
                [r[2], u[2], -f[2], p[2]],
                [0.0, 0.0, 0.0, 1.0],
            ],
            lens_mm,
            sensor_width_mm,
            resolution,
        }
    }

    /// Unit world direction of the ray through image point `(x, y)` in pixels, `(0, 0)`
    /// the top-left corner of the image and `(x + 0.5, y + 0.5)` the centre of pixel
    /// `(x, y)`.
    pub fn ray_direction(&self, x: f64, y: f64) -> [f64; 3] {
        let (w, h) = (self.resolution[0] as f64, self.resolution[1] as f64);
        // Blender's default sensor fit (AUTO) spans the sensor width over the larger image
        // side: the width of a landscape frame, the height of a portrait one.
        let half_sensor = 0.5 * self.sensor_width_mm / self.lens_mm;
        let (half_width, half_height) =
            if w >= h { (half_sensor, half_sensor * h / w) } else { (half_sensor * w / h, half_sensor) };
        let local = [(2.0 * x / w - 1.0) * half_width, (1.0 - 2.0 * y / h) * half_height, -1.0];
        let m = &self.matrix_world;
        let world = [
            m[0][0] * local[0] + m[0][1] * local[1] + m[0][2] * local[2],
            m[1][0] * local[0] + m[1][1] * local[1] + m[1][2] * local[2],
            m[2][0] * local[0] + m[2][1] * local[1] + m[2][2] * local[2],
        ];
        normalize(world)
    }

    /// The camera file contents, as the exporter writes them.
    pub fn to_json(&self, frame: i64) -> serde_json::Value {
        serde_json::json!({
            "frame": frame,
            "position": self.position,
            "matrix_world": self.matrix_world,
            "lens_mm": self.lens_mm,
            "sensor_width_mm": self.sensor_width_mm,
            "resolution": self.resolution,
        })
    }
}

/// The blockers file contents, as the exporter writes them.
pub fn blockers_json(frame: i64, spheres: &[Sphere]) -> serde_json::Value {
    let list: Vec<serde_json::Value> = spheres
        .iter()
        .map(|s| match s.object {
            0 => serde_json::json!({"center": s.center, "radius": s.radius}),
            object => serde_json::json!({"center": s.center, "radius": s.radius, "object": object}),
        })
        .collect();
    serde_json::json!({"frame": frame, "spheres": list})
}
