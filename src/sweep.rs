//! The speed/accuracy trade, measured: the quality presets and single-knob sweeps around
//! the default, each timed and compared with the ground-truth reference.
//!
//! Errors are in units of the unoccluded value: the radiance an unoccluded, upward-facing,
//! white diffuse surface receives from the scene's light (`integral L max(z, 0) / pi`,
//! luminance), so 0.01 means 1% of what an open white floor would show. They are taken
//! over the pixels the reference shades (alpha 1), on the mean of the three channels.
//!
//! The reference a sweep renders is direct light, so every configuration is shaded
//! without bounce light (`--bounces 0`): the sweep measures the direct light's method.

use crate::executor::{Executor, ExecutorError, ShadeJob};
use crate::plot::{pareto_front, Chart, Scale, Series};
use crate::scene::{Frame, Light, Scene};
use crate::sh::quadrature::gauss_legendre_on;
use crate::sh::ExpMethod;
use crate::shade::{frame_settings, Quality, ShadedFrame, ShadingSettings};
use crate::timing::StageTimings;
use serde::Serialize;
use std::time::Instant;

/// One measured configuration.
#[derive(Clone, Debug, Serialize)]
pub struct SweepRow {
    /// What was varied: "preset", "order", "epsilon", "exp", "directions", "level_step",
    /// "level_offset", "ratio_attenuation", "fitted_depths", "tangent_occlusion",
    /// "cap_detail" or "visibility_grid"; every other knob is the base's
    /// (fitted caps on).
    pub knob: String,
    /// The value, as a user would type it.
    pub value: String,
    pub order: usize,
    pub epsilon: f64,
    pub exp: String,
    pub directions: usize,
    pub level_step: f64,
    pub level_offset: f64,
    pub ratio_attenuation: bool,
    pub tangent_occlusion: bool,
    /// Best wall time of the repeats for the whole frame (tables included), in ms.
    pub milliseconds: f64,
    pub rmse: f64,
    pub mean_abs: f64,
    pub p99_abs: f64,
    pub max_abs: f64,
}

/// The configurations a sweep runs: the presets, then one knob at a time around
/// [`Quality::Default`].
pub fn configurations() -> Vec<(String, String, ShadingSettings)> {
    let mut out = Vec::new();
    for q in Quality::ALL {
        out.push(("preset".to_string(), q.name().to_string(), q.settings()));
    }
    let base = Quality::Default.settings();
    for order in 3..=8 {
        out.push((
            "order".into(),
            order.to_string(),
            ShadingSettings { order, epsilon: crate::shade::default_epsilon(order), ..base },
        ));
    }
    for epsilon in [0.02, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3] {
        out.push(("epsilon".into(), epsilon.to_string(), ShadingSettings { epsilon, ..base }));
    }
    for (name, exp) in
        [("quad", ExpMethod::Quad), ("hyb", ExpMethod::Hyb), ("ol", ExpMethod::Ol), ("series", ExpMethod::Series)]
    {
        out.push(("exp".into(), name.into(), ShadingSettings { exp, ..base }));
    }
    for directions in [8, 16, 32, 64] {
        let mut s = base;
        s.horizon.directions = directions;
        out.push(("directions".into(), directions.to_string(), s));
    }
    for level_step in [2.0, 4.0, 8.0] {
        let mut s = base;
        s.horizon.level_step = level_step;
        s.lamp_levels = None;
        out.push(("level_step".into(), level_step.to_string(), s));
    }
    for level_offset in [1.0, 2.0, 3.0, 4.0] {
        let mut s = base;
        s.horizon.level_offset = level_offset;
        s.lamp_levels = None;
        out.push(("level_offset".into(), level_offset.to_string(), s));
    }
    out.push(("ratio_attenuation".into(), "on".into(), ShadingSettings { ratio_attenuation: true, ..base }));
    out.push(("fitted_depths".into(), "off".into(), ShadingSettings { fitted_depths: false, ..base }));
    out.push(("tangent_occlusion".into(), "off".into(), ShadingSettings { tangent_occlusion: false, ..base }));
    out.push(("cap_detail".into(), "off".into(), ShadingSettings { cap_detail: false, ..base }));
    for visibility_grid in [2, 4] {
        out.push(("visibility_grid".into(), visibility_grid.to_string(), ShadingSettings { visibility_grid, ..base }));
    }
    for (_, _, settings) in &mut out {
        settings.bounce = crate::shade::bounce::BounceSettings::none();
    }
    out
}

/// Luminance of `integral L max(z, 0) / pi`: what an open white floor shows. Integrated
/// over the upper hemisphere only (64 Gauss nodes in `z`, 256 azimuths), so the cosine's
/// kink at the horizon costs no accuracy.
pub fn unoccluded_value(light: &Light) -> f64 {
    let azimuths = 256;
    let mut sum = 0.0;
    for (z, wz) in gauss_legendre_on(64, 0.0, 1.0) {
        let s = (1.0 - z * z).sqrt();
        for j in 0..azimuths {
            let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / azimuths as f64;
            let l = light.radiance([s * phi.cos(), s * phi.sin(), z]);
            let luminance = 0.2126 * l[0] as f64 + 0.7152 * l[1] as f64 + 0.0722 * l[2] as f64;
            sum += wz * luminance * z / std::f64::consts::PI;
        }
    }
    sum * 2.0 * std::f64::consts::PI / azimuths as f64
}

/// Error statistics of `image` against `reference` over the reference's shaded pixels, in
/// units of `unit`: (rmse, mean, 99th percentile, max) of the absolute error of the mean of
/// the three channels.
pub fn error_stats(image: &[[f32; 4]], reference: &[[f32; 4]], unit: f64) -> (f64, f64, f64, f64) {
    let mut errors: Vec<f64> = image
        .iter()
        .zip(reference)
        .filter(|(_, r)| r[3] > 0.5)
        .map(|(a, r)| ((a[0] + a[1] + a[2]) as f64 - (r[0] + r[1] + r[2]) as f64).abs() / 3.0 / unit)
        .collect();
    if errors.is_empty() {
        return (0.0, 0.0, 0.0, 0.0);
    }
    let n = errors.len() as f64;
    let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    let mean = errors.iter().sum::<f64>() / n;
    errors.sort_by(f64::total_cmp);
    let p99 = errors[((n * 0.99).ceil() as usize).clamp(1, errors.len()) - 1];
    (rmse, mean, p99, *errors.last().expect("non-empty"))
}

fn exp_name(exp: ExpMethod) -> &'static str {
    match exp {
        ExpMethod::Quad => "quad",
        ExpMethod::Hyb => "hyb",
        ExpMethod::Ol => "ol",
        ExpMethod::Series => "series",
        ExpMethod::Exact => "exact",
    }
}

/// Runs every configuration `repeats` times on one frame and scores the fastest run
/// against `reference`. `progress(done, total)` is called after each configuration.
pub fn run(
    executor: &Executor,
    scene: &Scene,
    frame: &Frame,
    reference: &[[f32; 4]],
    repeats: usize,
    progress: &dyn Fn(usize, usize),
) -> Result<Vec<SweepRow>, ExecutorError> {
    let unit = unoccluded_value(&frame.light).max(1e-12);
    let configurations = configurations();
    let total = configurations.len();
    let mut rows = Vec::with_capacity(total);
    for (done, (knob, value, settings)) in configurations.into_iter().enumerate() {
        let mut best = f64::INFINITY;
        let mut image = None;
        for _ in 0..repeats.max(1) {
            let started = Instant::now();
            let job = ShadeJob { resolving: None, ..ShadeJob::new(scene, frame, &settings) };
            let shaded: ShadedFrame = executor.shade(&job, &mut StageTimings::default())?;
            best = best.min(started.elapsed().as_secs_f64() * 1e3);
            image = Some(shaded);
        }
        let image = image.expect("at least one run");
        let (rmse, mean_abs, p99_abs, max_abs) = error_stats(&image.rgba, reference, unit);
        let marched = frame_settings(&settings, scene, frame).horizon;
        rows.push(SweepRow {
            knob,
            value,
            order: settings.order,
            epsilon: settings.epsilon,
            exp: exp_name(settings.exp).into(),
            directions: settings.horizon.directions,
            level_step: marched.level_step,
            level_offset: marched.level_offset,
            ratio_attenuation: settings.ratio_attenuation,
            tangent_occlusion: settings.tangent_occlusion,
            milliseconds: best,
            rmse,
            mean_abs,
            p99_abs,
            max_abs,
        });
        progress(done + 1, total);
    }
    Ok(rows)
}

/// The rows as CSV, one line each, with a header.
pub fn to_csv(rows: &[SweepRow]) -> String {
    let mut out = String::from(
        "knob,value,order,epsilon,exp,directions,level_step,level_offset,ratio_attenuation,tangent_occlusion,milliseconds,rmse,mean_abs,p99_abs,max_abs\n",
    );
    for r in rows {
        out.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{:.3},{:.6},{:.6},{:.6},{:.6}\n",
            r.knob,
            r.value,
            r.order,
            r.epsilon,
            r.exp,
            r.directions,
            r.level_step,
            r.level_offset,
            r.ratio_attenuation,
            r.tangent_occlusion,
            r.milliseconds,
            r.rmse,
            r.mean_abs,
            r.p99_abs,
            r.max_abs
        ));
    }
    out
}

/// Mean absolute error against time per frame, a series per knob, and the Pareto front.
pub fn chart(rows: &[SweepRow], scene_name: &str) -> Chart {
    let mut knobs: Vec<&str> = Vec::new();
    for r in rows {
        if !knobs.contains(&r.knob.as_str()) {
            knobs.push(&r.knob);
        }
    }
    let mut series: Vec<Series> = knobs
        .iter()
        .map(|knob| {
            let chosen: Vec<&SweepRow> = rows.iter().filter(|r| r.knob == *knob).collect();
            Series {
                name: knob.to_string(),
                points: chosen.iter().map(|r| (r.milliseconds, r.mean_abs)).collect(),
                line: false,
                labels: chosen.iter().map(|r| r.value.clone()).collect(),
            }
        })
        .collect();
    let points: Vec<(f64, f64)> = rows.iter().map(|r| (r.milliseconds, r.mean_abs)).collect();
    let front = pareto_front(&points);
    series.push(Series {
        name: "Pareto front".into(),
        points: front.iter().map(|&i| points[i]).collect(),
        line: true,
        labels: vec![],
    });
    Chart {
        title: format!("{scene_name}: mean absolute error against time per frame"),
        x_label: "time per frame (ms, CPU, best of repeats)".into(),
        y_label: "mean absolute error (units of the unoccluded value)".into(),
        x_scale: Scale::Log,
        y_scale: Scale::Log,
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_stats_use_shaded_pixels_and_the_unit() {
        let reference = [[1.0, 1.0, 1.0, 1.0], [0.5, 0.5, 0.5, 1.0], [9.0, 9.0, 9.0, 0.0]];
        let image = [[1.2, 1.2, 1.2, 1.0], [0.5, 0.5, 0.5, 1.0], [0.0, 0.0, 0.0, 0.0]];
        let (rmse, mean, p99, max) = error_stats(&image, &reference, 2.0);
        assert!((mean - 0.05).abs() < 1e-6 && (max - 0.1).abs() < 1e-6 && (p99 - 0.1).abs() < 1e-6);
        assert!((rmse - (0.01f64 / 2.0).sqrt()).abs() < 1e-6);
    }

    #[test]
    fn constant_white_light_has_unit_unoccluded_value() {
        assert!((unoccluded_value(&Light::Constant([1.0; 3])) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn configurations_cover_presets_and_every_knob() {
        let knobs: std::collections::BTreeSet<String> = configurations().into_iter().map(|c| c.0).collect();
        for k in [
            "preset",
            "order",
            "epsilon",
            "exp",
            "directions",
            "level_step",
            "level_offset",
            "ratio_attenuation",
            "fitted_depths",
            "tangent_occlusion",
            "cap_detail",
            "visibility_grid",
        ] {
            assert!(knobs.contains(k), "{k}");
        }
    }
}
