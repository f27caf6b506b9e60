//! What each command does, between parsed options and the library.

use crate::cli::{ExampleArgs, ExampleName, ShadeArgs};
use crate::scene::{output, Scene};
use crate::shade::shade_frame;
use anyhow::{anyhow, Context, Result};
use std::time::Instant;

/// `logsh shade`.
pub fn shade(args: &ShadeArgs) -> Result<()> {
    let settings = args.shading.settings().map_err(|e| anyhow!(e))?;
    let scene = Scene::load(&args.scene)?;
    let frame_number = args.frame.unwrap_or_else(|| scene.default_frame());
    let frame = scene.frame(frame_number)?;
    let started = Instant::now();
    let shaded = shade_frame(&scene, &frame, &settings)?;
    let elapsed = started.elapsed();
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create output directory {}", args.out.display()))?;
    let exr = args.out.join(format!("beauty.{frame_number:04}.exr"));
    let png = args.out.join(format!("beauty.{frame_number:04}.png"));
    for path in [&exr, &png] {
        scene.check_output_path(path)?;
    }
    output::write_exr_rgba(&exr, shaded.width, shaded.height, &shaded.rgba)?;
    output::write_png_preview(&png, shaded.width, shaded.height, &shaded.rgba)?;
    eprintln!(
        "shaded frame {frame_number} ({}x{}) at order {}, eps {}, {:?} in {:.2} s: {}",
        shaded.width,
        shaded.height,
        settings.order,
        settings.epsilon,
        settings.exp,
        elapsed.as_secs_f64(),
        exr.display()
    );
    Ok(())
}

/// `logsh example`.
pub fn example(args: &ExampleArgs) -> Result<()> {
    let name = match args.name {
        ExampleName::Dunes => "dunes",
        ExampleName::Spheres => "spheres",
    };
    let existing = args.out.join(crate::scene::SCENE_FILE);
    if existing.exists() {
        return Err(anyhow!(
            "{} already holds a scene; remove it or choose another --out (an existing scene is never overwritten)",
            args.out.display()
        ));
    }
    crate::synth::example_scene(
        name,
        &args.out,
        crate::synth::ExampleOptions { width: args.width, height: args.height, ..Default::default() },
    )
        .with_context(|| format!("cannot write example scene {name} to {}", args.out.display()))?;
    eprintln!("wrote example scene {name} to {}", args.out.display());
    Ok(())
}
