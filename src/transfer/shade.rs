//! A frame shaded on the CPU into its compositing passes and, from the same plan, its
//! transfer layers (`logsh render --transfer`).

use super::layers::{PixelTransfer, PrefilteredLobe, ShConvention, TransferFrame, TransferHeader};
use super::SunLampInputs;
use crate::heightfield::{HorizonPyramid, ScaleMax};
use crate::scene::{Frame, Light, LightSource, Scene};
use crate::sh::Real;
use crate::shade::compositing::{assemble, Pixel, ShadedPasses};
use crate::shade::frame::mirrored_suns;
use crate::shade::sun::SunDisk;
use crate::shade::{
    pixel_source, work_of, FramePlan, Occluders, PixelSource, PixelWork, PlannedKernel, SettingsError, ShadeError,
    ShadingKernel, ShadingSettings,
};
use clap::ValueEnum;
use rayon::prelude::*;

/// The passes of `frame` (as [`crate::shade::cpu::shade_plan`] shades them) and its
/// transfer layers.
pub fn shade_with_transfer(
    scene: &Scene,
    frame: &Frame,
    settings: &ShadingSettings,
) -> Result<(ShadedPasses, TransferFrame), ShadeError> {
    check_grid(settings)?;
    // A relight turns the light, which moves the detail over every cap: the frame is
    // shaded without it, so that a relight under the render's light gives it back.
    let settings = &ShadingSettings { cap_detail: false, ..*settings };
    let plan = FramePlan::new(scene, frame, settings)?;
    let pyramid = plan.terrain.as_ref().map(|terrain| terrain.horizon_pyramid(&plan.settings));
    let occluders = Occluders::of(&plan.blockers, pyramid.as_ref(), &plan.sun_shadows);
    let light = scene.light_source(frame.number)?;
    Ok(match plan.kernel.as_ref() {
        PlannedKernel::F32(kernel) => walk(kernel, occluders, &plan, light),
        PlannedKernel::F64(kernel) => walk(kernel, occluders, &plan, light),
    })
}

/// Transfer layers record each pixel's own transfer: a visibility grid is refused.
pub fn check_grid(settings: &ShadingSettings) -> Result<(), SettingsError> {
    if settings.visibility_grid > 1 {
        return Err(SettingsError::VisibilityGridWithout {
            grid: settings.visibility_grid,
            why: "--transfer records each pixel's own transfer",
            instead: "leave --visibility-grid at 1 with --transfer",
        });
    }
    Ok(())
}

/// The header of a frame shaded by `kernel` under `plan`, in `light` (the frame's, as
/// [`Scene::light_source`] tells it).
fn header<T: Real>(kernel: &ShadingKernel<T>, plan: &FramePlan, light: LightSource) -> TransferHeader {
    let window = plan.settings.light_window.to_possible_value().expect("every window has a name");
    TransferHeader {
        version: super::layers::TRANSFER_VERSION,
        scene: std::path::absolute(&plan.scene.dir).unwrap_or_else(|_| plan.scene.dir.clone()),
        frame: plan.frame.number,
        sh: ShConvention::of_order(kernel.order()),
        light,
        light_window: window.get_name().to_string(),
        sky_only: kernel.sky_only(),
        heightfield: plan.terrain.is_some(),
        blockers: !plan.blockers.is_empty(),
        lobes: kernel
            .prefiltered_lobes()
            .into_iter()
            .map(|(material, lobe, open)| PrefilteredLobe { material, lobe, open })
            .collect(),
        sun_lamps: plan.frame.suns.iter().map(|sun| sun.azimuth_elevation()).collect(),
        light_turn: plan.scene.light_turn,
        settings: Some(plan.settings),
        // What a relight shades its sharp lights again from: the Sun lamps, and the suns a
        // render with sharp lights takes out of a map.
        sun_lamp_inputs: (!plan.frame.suns.is_empty()
            || plan.settings.sharp_lights && matches!(*plan.frame.light, Light::Environment { .. }))
        .then(|| SunLampInputs::of(plan.scene, plan.frame)),
        view: plan.scene.view.absolute_spec(&plan.scene.dir),
        light_file_crc: plan.frame.light_file_crc,
        horizon_sectors: None,
        open_diffuse: kernel.open_diffuse().unwrap_or_default(),
    }
}

fn walk<T: Real>(
    kernel: &ShadingKernel<T>,
    occluders: Occluders,
    plan: &FramePlan,
    light: LightSource,
) -> (ShadedPasses, TransferFrame) {
    let frame = plan.frame;
    let g = &frame.gbuffer;
    let header = header(kernel, plan, light);
    let both = header.heightfield && header.blockers;
    let phong = plan.contents.phong;
    let scene_suns = frame.suns.len();
    // Each row's transfer is written in place, into layers allocated once.
    // The horizons marched bound those of the Sun lamps a relight turns and of the suns it
    // takes out of a map, in frames whose suns (the Sun lamps and the map's, as rendered)
    // the height field may shadow at some turn ([`crate::heightfield::HorizonsBetween`]).
    let shadowed = |pyramid: &HorizonPyramid, sun: &SunDisk| {
        sun.disk.march_band().is_some_and(|along| pyramid.may_rise_at_any_azimuth(along.band))
    };
    let bounding = |pyramid: &&HorizonPyramid| {
        pyramid.settings().scale_max == ScaleMax::Steps && kernel.suns.iter().any(|sun| shadowed(pyramid, sun))
    };
    let horizon_sectors = occluders.horizons.filter(bounding).map_or(0, HorizonPyramid::horizon_sectors);
    let mut transfer = TransferFrame::new(g.width, g.height, header, both, phong, horizon_sectors);
    let lobes = transfer.lobe_indices();
    let rows: Vec<Vec<Pixel>> = transfer
        .rows_mut()
        .into_par_iter()
        .enumerate()
        .map(|(y, mut row)| {
            let mut pixels = Vec::with_capacity(g.width);
            let sources: Vec<PixelSource> =
                (0..g.width).map(|x| pixel_source(&plan.scene.materials, frame, x, y)).collect();
            let work: Vec<PixelWork> = sources.iter().map(|source| work_of(frame, *source)).collect();
            let caps = kernel.sum_caps_of_work(occluders.blockers, &work);
            let mut shaded = 0;
            for (x, (work, source)) in work.into_iter().zip(sources).enumerate() {
                let (pixel, pixel_transfer) = match (work, source) {
                    (PixelWork::Shade { point, tint }, _) => {
                        shaded += 1;
                        let caps = caps.of(shaded - 1);
                        let (passes, point_transfer) = kernel.shade_transfer(occluders, &point, caps, scene_suns);
                        row.set(x, PixelTransfer::Surface { point: &point_transfer, tint }, &lobes);
                        pixels.push(Pixel::shaded(passes, tint));
                        continue;
                    }
                    (PixelWork::Fixed(colour), PixelSource::Background { ray }) => {
                        (Pixel::fixed(colour), PixelTransfer::Background { ray })
                    }
                    (PixelWork::Fixed(colour), PixelSource::WaterSky { tint, mirror }) => (
                        Pixel::fixed(colour),
                        PixelTransfer::Mirror { tint, mirror, suns: mirrored_suns(frame, mirror) },
                    ),
                    (PixelWork::Fixed(colour), PixelSource::WaterLamp { tint, radiance }) => {
                        (Pixel::fixed(colour), PixelTransfer::Lamp { tint, radiance })
                    }
                    (PixelWork::Fixed(_), PixelSource::Surface { .. }) => unreachable!("a surface is always shaded"),
                };
                row.set(x, pixel_transfer, &lobes);
                pixels.push(pixel);
            }
            pixels
        })
        .collect();
    let mut pixels = Vec::with_capacity(g.width * g.height);
    for row in rows {
        pixels.extend(row);
    }
    let passes = assemble(frame, &pixels);
    (transfer.position, transfer.normal) = (passes.position.clone(), passes.normal.clone());
    (passes, transfer)
}
