//! The CPU executor: a [`FramePlan`] shaded row-parallel with rayon, into a beauty image
//! (`logsh shade`, `bench`) or compositing passes (`logsh render`). It is the oracle the
//! GPU pass is compared with, and the fallback where no GPU can shade a frame.

use super::compositing::{assemble, Pixel};
use super::frame::{pixel_work, PixelWork, ShadedFrame, Tint};
use super::kernel::{Caps, KnownAlongSun, Occluders, ShadingKernel, SurfacePoint};
use super::plan::{FramePlan, PlannedKernel};
use super::shaded::{Outputs, Shaded};
use super::visibility_grid::{is_direct_surface, GridVisibility, VisibilityGrid};
use crate::scene::Material;
use crate::sh::Real;
use crate::timing::StageTimings;
use rayon::prelude::*;
use std::time::Instant;

/// Shades every pixel of `plan` into `outputs`, adding the stages "pyramid", "visibility
/// grid" and "shade" to `timings`.
pub fn shade_plan(plan: &FramePlan, outputs: Outputs, timings: &mut StageTimings) -> Shaded {
    let g = &plan.frame.gbuffer;
    match outputs {
        Outputs::Beauty => {
            let rgba = shade_plan_pixels::<[f32; 4]>(plan, timings);
            Shaded::Beauty(ShadedFrame { width: g.width, height: g.height, rgba })
        }
        Outputs::Passes => Shaded::Passes(assemble(plan.frame, &shade_plan_pixels::<Pixel>(plan, timings))),
    }
}

/// What the CPU executor writes per pixel.
trait PixelResult: Copy + Send + Sync {
    fn fixed(colour: [f32; 4]) -> Self;
    /// `known`: each sun's horizon at the point, marched with its row
    /// ([`ShadingKernel::suns_along_row`]), or empty to march it here.
    fn shaded<T: Real>(
        kernel: &ShadingKernel<T>,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        known: &[KnownAlongSun],
        tint: Tint,
    ) -> Self;
}

/// The beauty: RGBA, alpha 1 where a surface was shaded.
impl PixelResult for [f32; 4] {
    fn fixed(colour: [f32; 4]) -> Self {
        colour
    }

    fn shaded<T: Real>(
        kernel: &ShadingKernel<T>,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        known: &[KnownAlongSun],
        tint: Tint,
    ) -> Self {
        let (diffuse, specular) = kernel.shade_lobes_known(occluders, point, caps, Some(known));
        tint.beauty(diffuse, specular)
    }
}

/// The passes, the same pixels split (module doc of [`super::compositing`]).
impl PixelResult for Pixel {
    fn fixed(colour: [f32; 4]) -> Self {
        Pixel::fixed(colour)
    }

    fn shaded<T: Real>(
        kernel: &ShadingKernel<T>,
        occluders: Occluders,
        point: &SurfacePoint,
        caps: Caps,
        known: &[KnownAlongSun],
        tint: Tint,
    ) -> Self {
        Pixel::shaded(kernel.shade_passes_known(occluders, point, caps, Some(known)), tint)
    }
}

/// Filters the pyramid and shades every pixel of the plan, timing "pyramid" and "shade".
fn shade_plan_pixels<P: PixelResult>(plan: &FramePlan, timings: &mut StageTimings) -> Vec<P> {
    let started = Instant::now();
    let pyramid = plan.terrain.as_ref().map(|terrain| terrain.horizon_pyramid(&plan.settings));
    if pyramid.is_some() {
        timings.add_wall("pyramid", started);
    }
    let occluders = Occluders::of(&plan.blockers, pyramid.as_ref(), &plan.sun_shadows);
    match plan.kernel.as_ref() {
        PlannedKernel::F32(kernel) => shade_pixels::<P, f32>(kernel, occluders, plan, timings),
        PlannedKernel::F64(kernel) => shade_pixels::<P, f64>(kernel, occluders, plan, timings),
    }
}

/// Shades the frame row by row; the sphere caps of a row's points are summed first, in
/// packets ([`ShadingKernel::sum_caps`]).
///
/// With a visibility grid ([`ShadingSettings::visibility_grid`](super::ShadingSettings::visibility_grid) above 1, and something to
/// occlude), the horizons and caps of one pixel per block are computed first (the stage
/// "visibility grid"), and each pixel interpolates them ([`VisibilityGrid`]).
fn shade_pixels<P: PixelResult, T: Real>(
    kernel: &ShadingKernel<T>,
    occluders: Occluders,
    plan: &FramePlan,
    timings: &mut StageTimings,
) -> Vec<P> {
    let (frame, materials) = (plan.frame, &plan.scene.materials);
    let g = &frame.gbuffer;
    let work_at = |x, y| pixel_work(materials, frame, x, y);
    let occluded = occluders.horizons.is_some() || occluders.blockers.is_some();
    let started = Instant::now();
    let grid = (plan.settings.visibility_grid > 1 && occluded)
        .then(|| VisibilityGrid::new(kernel, occluders, frame, materials, plan.settings.visibility_grid, work_at));
    if grid.is_some() {
        timings.add_wall("visibility grid", started);
    }
    let started = Instant::now();
    let mut pixels = vec![P::fixed([0.0; 4]); g.width * g.height];
    let suns = kernel.suns.len();
    pixels.par_chunks_mut(g.width).enumerate().for_each(|(y, row)| {
        let work: Vec<PixelWork> = (0..g.width).map(|x| work_at(x, y)).collect();
        let points = PixelWork::points(&work);
        let known = kernel.suns_along_row(occluders.horizons, &points);
        let known_of = |k: usize| known.get(k * suns..(k + 1) * suns).unwrap_or(&[]);
        let caps = match &grid {
            Some(_) => Default::default(),
            None => kernel.sum_caps(occluders.blockers, &points),
        };
        let mut interpolated = GridVisibility::new();
        let mut shaded = 0;
        for (x, (out, work)) in row.iter_mut().zip(work).enumerate() {
            *out = match work {
                PixelWork::Fixed(colour) => P::fixed(colour),
                PixelWork::Shade { point, tint } => {
                    shaded += 1;
                    let caps = match &grid {
                        None => caps.of(shaded - 1),
                        Some(grid) => {
                            let direct = is_direct_surface(materials, frame, g.index(x, y));
                            // A Phong lobe's specular occlusion reads the horizons.
                            let glossy = matches!(materials.get(&point.material), Some(Material::Phong { .. }));
                            match direct && grid.at(x, y, &point, glossy, &mut interpolated) {
                                true => interpolated.caps(),
                                false => Caps::Walk,
                            }
                        }
                    };
                    P::shaded(kernel, occluders, &point, caps, known_of(shaded - 1), tint)
                }
            };
        }
    });
    timings.add_wall("shade", started);
    pixels
}
