//! Shared test helpers: hard inputs and an approximate-equality assertion that prints the
//! actual difference.
#![allow(dead_code)]

pub mod cli;
pub mod executors;
pub mod sharp;

pub use executors::*;

/// `sphere_over_plane`'s plane with no spheres, `width` x `height` pixels, written to a
/// temporary directory and loaded; the directory lasts as long as the returned guard.
pub fn open_plane(width: u32, height: u32) -> (tempfile::TempDir, logsh::scene::Scene) {
    let dir = tempfile::tempdir().unwrap();
    let spec = logsh::synth::SphereOverPlane { spheres: vec![], width, height, ..Default::default() };
    logsh::synth::sphere_over_plane(dir.path(), &spec).unwrap();
    let scene = logsh::scene::Scene::load(dir.path()).unwrap();
    (dir, scene)
}

/// `to`, made a copy of the files of the scene directory `from` (its folders left out).
pub fn copy_scene(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        if entry.path().is_file() {
            std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
        }
    }
}

/// Every channel of a single-part EXR as f32, by full name.
pub fn exr_channels(path: &std::path::Path) -> std::collections::HashMap<String, Vec<f32>> {
    use exr::prelude::{read_all_flat_layers_from_file, FlatSamples};
    let image = read_all_flat_layers_from_file(path).unwrap();
    let layer = &image.layer_data[0];
    layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            let values = match &c.sample_data {
                FlatSamples::F16(v) => v.iter().map(|h| h.to_f32()).collect(),
                FlatSamples::F32(v) => v.clone(),
                FlatSamples::U32(v) => v.iter().map(|&u| u as f32).collect(),
            };
            (c.name.to_string(), values)
        })
        .collect()
}

/// Asserts `|actual - expected| <= tolerance` for scalars or slices, printing the worst
/// entry and its difference.
#[macro_export]
macro_rules! assert_close {
    ($actual:expr, $expected:expr, $tol:expr, $($ctx:tt)+) => {{
        let actual: Vec<f64> = $actual.iter().map(|v| *v as f64).collect();
        let expected: Vec<f64> = $expected.iter().map(|v| *v as f64).collect();
        assert_eq!(actual.len(), expected.len(), "length mismatch: {}", format!($($ctx)+));
        let (worst, diff) = actual
            .iter()
            .zip(&expected)
            .map(|(a, e)| (a - e).abs())
            .enumerate()
            .fold((0, 0.0f64), |acc, (i, d)| if !(d <= acc.1) { (i, d) } else { acc });
        assert!(
            diff <= $tol,
            "{}: entry {} differs by {:.3e} > {:.1e} (actual {:.12}, expected {:.12})",
            format!($($ctx)+), worst, diff, $tol, actual[worst], expected[worst]
        );
    }};
}

/// Directions that break careless code: the poles, the equator, axis-aligned and nearly
/// axis-aligned vectors, and a generic one.
pub fn hard_directions() -> Vec<[f64; 3]> {
    let mut dirs: Vec<[f64; 3]> = vec![
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [1e-9, 0.0, 1.0],
        [0.3, -0.5, 0.8],
        [-0.7, 0.2, -0.1],
    ];
    for d in dirs.iter_mut() {
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        *d = [d[0] / n, d[1] / n, d[2] / n];
    }
    dirs
}

pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// A fixed pseudo-random sequence in [0, 1) for test inputs.
pub struct TestRng(pub u64);
impl TestRng {
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn vector(&mut self, len: usize, scale: f64) -> Vec<f64> {
        (0..len).map(|_| scale * (2.0 * self.next() - 1.0)).collect()
    }
}
