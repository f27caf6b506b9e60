//! Mean and worst absolute error against the closed form `1 - sin^2(alpha) cos(beta)` on
//! sphere-over-plane scenes (format v1, Blender 5 layout, constant white light, albedo 1,
//! no height field), per order, eps, exponentiation and tangent occlusion.
//!
//! `cargo run --release --example sphere_accuracy [-- --quick]`: `--quick` runs only the
//! defaults' method and tangent setting (`quad`, tangent occlusion on) over every order and
//! eps, a minute instead of an hour; `--defaults` runs every method at each order's
//! default eps.
use logsh::executor::{Executor, ShadeJob};
use logsh::scene::Scene;
use logsh::sh::ExpMethod;
use logsh::shade::{ShadedFrame, ShadingSettings};
use logsh::synth::{analytic_placements, sphere_over_plane, SphereOverPlane};
use logsh::timing::StageTimings;

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let defaults = std::env::args().any(|a| a == "--defaults");
    let dir = std::env::temp_dir().join(format!("logsh-sphere-accuracy-{}", std::process::id()));
    let mut scenes = Vec::new();
    for (i, spheres) in analytic_placements().into_iter().enumerate() {
        let spec = SphereOverPlane { spheres, width: 160, height: 90, ..Default::default() };
        let path = dir.join(format!("scene{i}"));
        sphere_over_plane(&path, &spec).expect("write scene");
        let scene = Scene::load(&path).expect("load scene");
        let frame = scene.frame(1).expect("load frame");
        let expected = spec.expected_image(&frame.gbuffer);
        scenes.push((scene, frame, expected));
    }
    let orders: Vec<usize> = (3..=8).collect();
    let sweep = [0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.2];
    let methods = if quick {
        vec![ExpMethod::Quad]
    } else {
        vec![ExpMethod::Exact, ExpMethod::Quad, ExpMethod::Hyb, ExpMethod::Ol, ExpMethod::Series]
    };
    println!("order eps    exp     tangent  mean_abs  worst_scene_mean  max_abs");
    for order in orders {
        let epsilons = if defaults { vec![logsh::shade::default_epsilon(order)] } else { sweep.to_vec() };
        for &epsilon in &epsilons {
            for &method in &methods {
                let tangents: &[bool] = if quick || defaults { &[true] } else { &[true, false] };
                for &tangent in tangents {
                    let mut settings = ShadingSettings::for_order(order);
                    settings.epsilon = epsilon;
                    settings.exp = method;
                    settings.tangent_occlusion = tangent;
                    // The closed forms are direct light.
                    settings.bounce.bounces = 0;
                    let (mut sum, mut count, mut worst_mean, mut max_abs) = (0.0, 0usize, 0.0f64, 0.0f64);
                    for (scene, frame, expected) in &scenes {
                        let job = ShadeJob::new(scene, frame, &settings);
                        let shaded: ShadedFrame =
                            Executor::cpu().shade(&job, &mut StageTimings::default()).expect("shade");
                        let (mut s, mut c) = (0.0, 0usize);
                        for (px, e) in shaded.rgba.iter().zip(expected) {
                            if let Some(e) = e {
                                let err = (px[0] as f64 - e).abs();
                                s += err;
                                c += 1;
                                max_abs = max_abs.max(err);
                            }
                        }
                        worst_mean = worst_mean.max(s / c as f64);
                        sum += s;
                        count += c;
                    }
                    println!(
                        "{order:5} {epsilon:<6} {:<7} {:<8} {:.4}    {:.4}            {:.4}",
                        format!("{method:?}"),
                        tangent,
                        sum / count as f64,
                        worst_mean,
                        max_abs
                    );
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
