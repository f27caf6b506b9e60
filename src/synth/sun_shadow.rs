//! A sun's shadow map of a synthetic frame's spheres, as the Blender exporter renders one
//! of the blocker meshes ([`crate::scene::sun_shadow`]): ray cast along `-axis` from the
//! centre of each texel for the first surface, and back along `axis` from beyond the
//! spheres for the last.

use super::raycast::{trace, Object, Shape};
use crate::scene::sun_shadow::SunShadowMap;
use crate::vector::{dot, frame_around};
use std::path::PathBuf;

/// What the exporter writes where a texel's ray meets nothing (Blender's depth pass).
const NOTHING: f32 = 1e10;

/// The map towards unit `axis` of the sphere objects among `objects`, `long` texels along
/// its longer side, covering their projection with two texels to spare; `None` without a
/// sphere.
pub fn sun_shadow_map(objects: &[Object], axis: [f64; 3], long: usize) -> Option<SunShadowMap> {
    let spheres: Vec<Object> = objects.iter().filter(|o| matches!(o.shape, Shape::Sphere { .. })).cloned().collect();
    let (right, up) = frame_around(axis);
    let (mut low, mut high) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for o in &spheres {
        let Shape::Sphere { center, radius } = o.shape else { continue };
        for (k, e) in [right, up, axis].iter().enumerate() {
            low[k] = low[k].min(dot(center, *e) - radius);
            high[k] = high[k].max(dot(center, *e) + radius);
        }
    }
    if spheres.is_empty() {
        return None;
    }
    let extent = [high[0] - low[0], high[1] - low[1]];
    let texel = extent[0].max(extent[1]) / (long - 4) as f64;
    let (columns, rows) = ((extent[0] / texel).ceil() as usize + 4, (extent[1] / texel).ceil() as usize + 4);
    let size = [columns as f64 * texel, rows as f64 * texel];
    let middle = [0.5 * (low[0] + high[0]), 0.5 * (low[1] + high[1]), high[2] + 1.0];
    let origin = [0, 1, 2].map(|k| middle[0] * right[k] + middle[1] * up[k] + middle[2] * axis[k]);
    let down = axis.map(|c| -c);
    let beyond = high[2] - low[2] + 2.0;
    let (mut depths, mut far_depths) = (Vec::with_capacity(columns * rows), Vec::with_capacity(columns * rows));
    for j in 0..rows {
        for i in 0..columns {
            let u = ((i as f64 + 0.5) / columns as f64 - 0.5) * size[0];
            let v = (0.5 - (j as f64 + 0.5) / rows as f64) * size[1];
            let from = [0, 1, 2].map(|k| origin[k] + u * right[k] + v * up[k]);
            let below = [0, 1, 2].map(|k| from[k] - beyond * axis[k]);
            depths.push(trace(&spheres, from, down, 0.0).map_or(NOTHING, |hit| hit.t as f32));
            far_depths.push(trace(&spheres, below, axis, 0.0).map_or(NOTHING, |hit| (beyond - hit.t) as f32));
        }
    }
    Some(SunShadowMap {
        file: PathBuf::from("sun_shadow.exr"),
        axis,
        origin,
        right,
        up,
        size,
        columns,
        rows,
        depths,
        far_depths,
    })
}
