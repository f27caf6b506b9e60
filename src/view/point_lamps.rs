//! The scene's point lamps on the page's map of the light. A point lamp has a place, not a
//! direction, and stays where it is when the environment turns (`--light-rotation`), so
//! the map marks it where it lies as seen from the middle of the frame's surface.

use crate::scene::{Scene, SceneError};
use crate::transfer::TransferFrame;
use crate::vector::{dot, sub};

/// The frame's point lamps (its own where scene.json's `per_frame` moves them) as azimuth
/// and elevation in degrees, as a sun's ([`crate::scene::SunLight::azimuth_elevation`]),
/// seen from the mean position of the frame's surface pixels. None where the frame shows
/// no surface; a lamp at that very point is left out.
pub fn point_lamp_directions(frame: &TransferFrame) -> Result<Vec<[f64; 2]>, SceneError> {
    let scene = Scene::load_description(&frame.header.scene)?;
    let points = match scene.changes(frame.header.frame)?.lamps {
        Some((_, points)) => points,
        None => scene.points,
    };
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let surface = frame
        .position
        .iter()
        .zip(&frame.alpha)
        .filter(|(p, &alpha)| alpha > 0.0 && p.iter().all(|v| v.is_finite()))
        .map(|(p, _)| p.map(f64::from));
    let (sum, count) =
        surface.fold(([0.0; 3], 0usize), |(sum, count), p| ([sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]], count + 1));
    if count == 0 {
        return Ok(Vec::new());
    }
    let middle = sum.map(|v| v / count as f64);
    Ok(points
        .iter()
        .filter_map(|lamp| {
            let towards = sub(lamp.position, middle);
            let length = dot(towards, towards).sqrt();
            let [x, y, z] = towards;
            (length > 0.0).then(|| [y.atan2(x).to_degrees(), (z / length).clamp(-1.0, 1.0).asin().to_degrees()])
        })
        .collect())
}
