//! A point to shade, as every stage of the per-pixel pipeline sees it.

/// A point to shade: where, which way it faces, from where it is seen, what it is made of.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    pub position: [f64; 3],
    /// Unit normal.
    pub normal: [f64; 3],
    /// The eye (or, for a point seen in water, the water surface point).
    pub view_origin: [f64; 3],
    pub material: u32,
    /// Object index (0: none); the spheres of this object that hold the point cast no
    /// shadow on it.
    pub object: u32,
}

/// How far above the ground plane a receiver must be for the plane to occlude it: the
/// ground's own pixels (on it to f32 rounding) are left to their tangent plane.
pub fn above_ground(p: [f64; 3], ground: f64) -> bool {
    p[2] > ground + 1e-4 * (1.0 + ground.abs())
}

/// The view direction mirrored about `n`: `R = 2 (n . V) n - V`, `V` from `p` towards
/// the eye. Falls back to `n` when the eye sits on `p`.
pub fn reflect_view(eye: [f64; 3], p: [f64; 3], n: [f64; 3]) -> [f64; 3] {
    let Some(v) = towards_eye(eye, p) else { return n };
    let d = 2.0 * (n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
    [d * n[0] - v[0], d * n[1] - v[1], d * n[2] - v[2]]
}

/// The unit direction `V` from `p` towards the eye, or `n` when the eye sits on `p`.
pub fn view_direction(eye: [f64; 3], p: [f64; 3], n: [f64; 3]) -> [f64; 3] {
    towards_eye(eye, p).unwrap_or(n)
}

fn towards_eye(eye: [f64; 3], p: [f64; 3]) -> Option<[f64; 3]> {
    let v = [eye[0] - p[0], eye[1] - p[1], eye[2] - p[2]];
    let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (length > 0.0).then(|| v.map(|c| c / length))
}
