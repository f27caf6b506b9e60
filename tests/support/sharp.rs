//! What the sharp-light tests share (`tests/suns.rs`, `tests/point_lamps.rs`): a light over
//! a sphere and a plane measured against its closed form on the plane, by the CPU path and
//! by the reference; scene.json with a given `lights`; and the finiteness check of extreme
//! lights.

use logsh::reference::{render_reference, Integration, ReferenceLight, ReferenceOptions};
use logsh::scene::{Frame, Scene, SceneError};
use logsh::shade::{ShadedFrame, ShadingSettings};
use logsh::synth::PLANE_MATERIAL;
use std::path::Path;

/// The plane's pixels of one frame, shaded by the CPU path (default settings) and by the
/// reference (tolerance 2e-3), against a closed form; errors relative to the open plane.
pub struct PlaneComparison {
    pub pixels: usize,
    /// Pixels whose closed form is between 2 % and 98 % of the open plane.
    pub penumbra: usize,
    pub fast: f64,
    pub fast_worst: f64,
    pub reference: f64,
    pub reference_worst: f64,
}

impl PlaneComparison {
    /// `closed_form(p)` is the plane's value at `p` and the open plane's there.
    pub fn measure(scene: &Scene, frame: &Frame, closed_form: impl Fn([f64; 3]) -> (f64, f64)) -> Self {
        let shaded = super::cpu_beauty(scene, frame, &ShadingSettings::default()).unwrap();
        let options = ReferenceOptions {
            light: ReferenceLight::EnvironmentMap,
            integration: Integration::Auto,
            tolerance: 2e-3,
            max_level: 6,
            ..Default::default()
        };
        let truth = render_reference(scene, frame, &options, &|_| {}).unwrap();
        let (mut fast, mut reference, mut pixels, mut penumbra) = (0.0, 0.0, 0usize, 0usize);
        let (mut fast_worst, mut reference_worst) = (0.0f64, 0.0f64);
        for (i, &m) in frame.gbuffer.material.iter().enumerate() {
            if m != PLANE_MATERIAL {
                continue;
            }
            let (expected, open) = closed_form(frame.gbuffer.position[i].map(f64::from));
            let e_fast = (f64::from(shaded.rgba[i][0]) - expected).abs() / open;
            let e_reference = (f64::from(truth.rgba[i][0]) - expected).abs() / open;
            fast += e_fast;
            reference += e_reference;
            fast_worst = fast_worst.max(e_fast);
            reference_worst = reference_worst.max(e_reference);
            pixels += 1;
            penumbra += usize::from(expected > 0.02 * open && expected < 0.98 * open);
        }
        let (fast, reference) = (fast / pixels as f64, reference / pixels as f64);
        Self { pixels, penumbra, fast, fast_worst, reference, reference_worst }
    }

    /// Prints the figures for `what` and asserts them: a penumbra to test, the CPU path
    /// within 3e-3 on average and 0.06 at worst (the disk is 32 directions, each a soft
    /// patch), the reference within 2e-3 and 0.02 (it samples the disk to 1e-3 of the
    /// value, and the cosine varies over it).
    pub fn assert_close(&self, what: &str) {
        let Self { pixels, penumbra, fast, fast_worst, reference, reference_worst } = self;
        println!(
            "{what}, {pixels} plane pixels ({penumbra} in the penumbra), relative to the open plane: CPU mean \
             {fast:.1e} max {fast_worst:.3}; reference mean {reference:.1e} max {reference_worst:.3}"
        );
        assert!(*penumbra > 20, "{what}: the shadow must have a penumbra to test: {penumbra} pixels");
        assert!(*fast <= 3e-3, "{what}: CPU mean error {fast}");
        assert!(*fast_worst <= 0.06, "{what}: CPU worst pixel {fast_worst}");
        assert!(*reference <= 2e-3, "{what}: reference mean error {reference}");
        assert!(*reference_worst <= 0.02, "{what}: reference worst pixel {reference_worst}");
    }
}

/// Rewrites the scene.json in `dir` with `lights` as its `lights`, and loads it.
pub fn load_with_lights(dir: &Path, lights: serde_json::Value) -> Result<Scene, SceneError> {
    let file = dir.join("scene.json");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    json["lights"] = lights;
    std::fs::write(&file, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    Scene::load(dir)
}

/// Every output of `shaded` is finite and `>= 0`; with `below`, no plane pixel of `frame`
/// is lit (the light is under the plane).
pub fn assert_finite(shaded: &ShadedFrame, frame: &Frame, below: bool, what: &str) {
    assert!(
        shaded.rgba.iter().all(|p| p.iter().all(|v| v.is_finite() && *v >= 0.0)),
        "{what}: non-finite or negative pixel"
    );
    if below {
        let mut plane = shaded.rgba.iter().zip(&frame.gbuffer.material).filter(|(_, &m)| m == PLANE_MATERIAL);
        assert!(plane.all(|(p, _)| p[0] < 1.5), "{what}: a light under the plane lights it");
    }
}
