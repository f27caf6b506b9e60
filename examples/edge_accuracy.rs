//! Anti-aliased edges against Cycles: a scene exported point-sampled and supersampled
//! (`export_scene.py --supersample N`), both shaded, against one Cycles render with the
//! same pixel filter (`render_cycles.py --filter box1` or `blackman-harris`):
//!
//! ```text
//! cargo run --release --example edge_accuracy -- POINT_SCENE SUPERSAMPLED_SCENE CYCLES.exr [box|blackman-harris]
//! ```
//!
//! Edge pixels are those whose samples in the supersampled G-buffer differ in material or
//! object (geometric edges, the background's included). Errors are `logsh::compare`'s
//! (mean absolute, RGB, over the open white floor), over the edge pixels and over every
//! pixel; times are the medians of 3 shadings of each frame, adaptive and every sample,
//! in one run on the CPU.

use logsh::compare::{read_rgb, unoccluded_value};
use logsh::executor::{Executor, ShadeJob};
use logsh::scene::{Frame, Scene};
use logsh::shade::{PixelFilter, Resolving, ShadedFrame, ShadingSettings};
use logsh::timing::StageTimings;
use std::path::Path;
use std::time::Instant;

fn shade(executor: &Executor, scene: &Scene, frame: &Frame, resolving: Resolving) -> (Vec<[f32; 3]>, f64) {
    let settings = ShadingSettings::default();
    let mut times = Vec::new();
    let mut image = Vec::new();
    for _ in 0..3 {
        let started = Instant::now();
        let job = ShadeJob { resolving: Some(resolving), ..ShadeJob::new(scene, frame, &settings) };
        let shaded: ShadedFrame = executor.shade(&job, &mut StageTimings::default()).expect("shaded");
        times.push(started.elapsed().as_secs_f64());
        image = shaded.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect();
    }
    times.sort_by(f64::total_cmp);
    (image, times[1])
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [point, sampled, truth] = [&args[0], &args[1], &args[2]].map(Path::new);
    let filter = match args.get(3).map(String::as_str) {
        Some("blackman-harris") => PixelFilter::BlackmanHarris,
        _ => PixelFilter::Box,
    };
    let executor = Executor::cpu();
    let (point_scene, sampled_scene) = (Scene::load(point)?, Scene::load(sampled)?);
    let (point_frame, sampled_frame) = (point_scene.frame(1)?, sampled_scene.frame(1)?);
    let (_, _, truth) = read_rgb(truth)?;
    let floor = unoccluded_value(&point_frame).expect("a map or constant light");
    let n = sampled_frame.supersample;
    let g = &sampled_frame.gbuffer;
    let (width, height) = (g.width / n, g.height / n);
    let edge: Vec<bool> = (0..width * height)
        .map(|p| {
            let (x, y) = (p % width, p / width);
            let first = g.index(x * n, y * n);
            (0..n * n).any(|k| {
                let i = g.index(x * n + k % n, y * n + k / n);
                g.material[i] != g.material[first] || g.object_at(i) != g.object_at(first)
            })
        })
        .collect();
    let error = |image: &[[f32; 3]], only_edges: bool| {
        let pixels: Vec<usize> = (0..image.len()).filter(|&p| !only_edges || edge[p]).collect();
        let sum: f64 = pixels
            .iter()
            .map(|&p| {
                (0..3).map(|k| (f64::from(image[p][k]) - f64::from(truth[p][k])).abs() / floor[k]).sum::<f64>() / 3.0
            })
            .sum();
        sum / pixels.len() as f64
    };
    let resolving = Resolving { filter, every_sample: false };
    let (point_image, point_time) = shade(&executor, &point_scene, &point_frame, resolving);
    let (adaptive_image, adaptive_time) = shade(&executor, &sampled_scene, &sampled_frame, resolving);
    let every = Resolving { every_sample: true, ..resolving };
    let (every_image, every_time) = shade(&executor, &sampled_scene, &sampled_frame, every);
    let edges = edge.iter().filter(|&&e| e).count();
    println!("{width}x{height}, {n}x{n} samples, {filter:?} filter, {edges} edge pixels");
    println!("| frame | edge pixels' error | every pixel's error | shading time | against point-sampled |");
    println!("| --- | --- | --- | --- | --- |");
    for (name, image, time) in [
        ("point-sampled", &point_image, point_time),
        ("supersampled, adaptive", &adaptive_image, adaptive_time),
        ("supersampled, every sample", &every_image, every_time),
    ] {
        println!(
            "| {name} | {:.4} | {:.4} | {:.3} s | {:.2}x |",
            error(image, true),
            error(image, false),
            time,
            time / point_time
        );
    }
    Ok(())
}
