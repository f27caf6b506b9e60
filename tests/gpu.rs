//! The GPU pass against the CPU path (the oracle), on lavapipe in CI.
mod support;

use logsh::gpu::Gpu;
use logsh::scene::Scene;
use logsh::shade::{shade_frame, ShadingSettings};
use std::path::Path;

#[test]
fn smoke() {
    let gpu = Gpu::new().expect("adapter");
    eprintln!("{}", gpu.adapter());
    for name in ["spheres", "dunes"] {
        let scene = Scene::load(&Path::new("gbuffers").join(name)).unwrap();
        let frame = scene.frame(scene.default_frame()).unwrap();
        let settings = ShadingSettings::for_order(4);
        let t = std::time::Instant::now();
        let cpu = shade_frame(&scene, &frame, &settings).unwrap();
        let tc = t.elapsed();
        let t = std::time::Instant::now();
        let (g, timings) = gpu.shade_frame_timed(&scene, &frame, &settings, true).unwrap();
        let tg = t.elapsed();
        let mut worst = 0.0f32;
        let mut sum = 0.0f64;
        for (a, b) in cpu.rgba.iter().zip(&g.rgba) {
            for c in 0..4 { worst = worst.max((a[c]-b[c]).abs()); sum += (a[c]-b[c]).abs() as f64; }
        }
        eprintln!("{name}: worst {worst} mean {} cpu {:?} gpu {:?} {:?}", sum / (cpu.rgba.len()*4) as f64, tc, tg, timings);
    }
}
