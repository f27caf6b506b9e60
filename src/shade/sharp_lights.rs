//! Light decomposition: the compact bright regions of an environment map (suns, which
//! HDRI libraries ship a few texels wide and carrying most of the light) are taken out
//! into [`SunLight`]s, shaded per pixel by [`super::sun`], and the residual stays in SH.
//! Order-n SH cannot hold a light a degree wide: its projection rings, and the
//! exponentiated visibility blurs its shadow over tens of degrees (SN08, paper 004,
//! Section 4, treats such key lights apart from the environment).
//!
//! # Which regions are suns
//!
//! Repeatedly, from the brightest texel left (Rec. 709 luminance), while it is at least
//! [`SUN_CONTRAST`] times the map's median luminance: its 8-connected region of texels
//! at least [`REGION_FLOOR`] of its luminance (wrapping in azimuth) is a sun when it lies
//! within [`MAX_SUN_RADIUS`] of its centre and carries at least [`MIN_SUN_SHARE`] of the
//! map's power. Its light is what it carries above the mean radiance of the texels
//! around it (the background, which the region's texels are set to in the residual), so
//! the residual plus the suns hold exactly the map's power. The sun's direction is the
//! power-weighted mean of its texels' directions; its angular radius is
//! `sqrt(2 <theta^2>)` (a uniform disk's, from the power-weighted second moment about
//! that direction), at least the radius of one texel, which is all a map can say of a
//! sun narrower than a texel.

use crate::scene::{EnvironmentMap, Light, SunLight};
use std::f64::consts::PI;
use std::sync::{Arc, Mutex};

/// The brightest texel must be this many times the median luminance to start a sun.
pub const SUN_CONTRAST: f64 = 50.0;
/// A sun's region: the texels at least this fraction of its peak's luminance.
pub const REGION_FLOOR: f64 = 0.01;
/// A region reaching further than this from its centre (radians, 10 degrees) is a bright
/// area of the sky (a window, an overcast glow), which SH holds well enough, not a sun.
pub const MAX_SUN_RADIUS: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// A region below this share of the map's power is left in SH.
pub const MIN_SUN_SHARE: f64 = 0.02;
/// Most suns taken from one map.
pub const MAX_EXTRACTED_SUNS: usize = 4;
/// Most candidate regions examined (each costs a pass over the map).
const MAX_REGIONS_TRIED: usize = 16;

const LUMINANCE: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// What was taken out of a map, and what is left.
#[derive(Clone, Debug)]
pub struct Decomposition {
    /// The map with every sun's region set to its background.
    pub residual: EnvironmentMap,
    /// The suns, in the map's units times `strength`.
    pub suns: Vec<SunLight>,
    /// Each sun's share of the map's power (luminance), in the same order.
    pub shares: Vec<f64>,
}

/// A light's [`Decomposition`], its residual as the light the SH holds (the residual map
/// at the light's strength), which a plan reads in place.
pub struct LightSplit {
    pub suns: Vec<SunLight>,
    pub shares: Vec<f64>,
    pub residual: Light,
}

/// The last light's split, per process, with the light it was made of (held, so that its
/// address cannot be reused by another).
static LAST_SPLIT: Mutex<Option<(Arc<Light>, Arc<LightSplit>)>> = Mutex::new(None);

/// [`extract_suns`] of `light`'s map, or `None` for a light without one; made once for
/// consecutive calls on the same light, so `logsh render` and `logsh shade` print the
/// suns and their first frame's plan takes them out of one decomposition.
pub fn decomposition(light: &Arc<Light>) -> Option<Arc<LightSplit>> {
    let Light::Environment { map, strength } = light.as_ref() else {
        return None;
    };
    let last = || LAST_SPLIT.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((_, split)) = last().as_ref().filter(|(previous, _)| Arc::ptr_eq(previous, light)) {
        return Some(split.clone());
    }
    let Decomposition { residual, suns, shares } = extract_suns(map, *strength);
    let split =
        Arc::new(LightSplit { suns, shares, residual: Light::Environment { map: residual, strength: *strength } });
    *last() = Some((light.clone(), split.clone()));
    Some(split)
}

/// Splits `map` (times `strength`) into suns and a residual (module doc).
///
/// The texels' luminances are taken once and their directions from a sine and cosine per
/// row and per column (the same products as
/// [`equirectangular_to_direction`](crate::scene::light::equirectangular_to_direction)),
/// the median by selection, and a region's masks are cleared where they were set: the
/// same suns and residual, bit for bit, as a luminance and a direction per visit, a sorted
/// copy and fresh masks per region tried.
pub fn extract_suns(map: &EnvironmentMap, strength: f32) -> Decomposition {
    let (width, height) = (map.width, map.height);
    let lum = |t: [f32; 3]| (0..3).map(|k| LUMINANCE[k] * f64::from(t[k])).sum::<f64>();
    let mut luminance: Vec<f64> = map.texels.iter().map(|&t| lum(t)).collect();
    let sky = SkyTexels::of(width, height, map);
    let total: f64 = luminance.iter().enumerate().map(|(i, &l)| l * sky.solid_angle[i / width]).sum();
    let median = {
        let mut order = luminance.clone();
        let middle = order.len() / 2;
        *order.select_nth_unstable_by(middle, f64::total_cmp).1
    };
    let mut out = Decomposition { residual: map.clone(), suns: Vec::new(), shares: Vec::new() };
    if !(total > 0.0 && strength > 0.0) {
        return out;
    }
    let mut tried = vec![false; width * height];
    let mut region = Region::new(width * height);
    for _ in 0..MAX_REGIONS_TRIED {
        if out.suns.len() == MAX_EXTRACTED_SUNS {
            break;
        }
        let Some(peak) = brightest_untried(&luminance, &tried) else {
            break;
        };
        let peak_lum = luminance[peak];
        if !(peak_lum >= SUN_CONTRAST * median && peak_lum > 0.0) {
            break;
        }
        region.grow(peak, REGION_FLOOR * peak_lum, &luminance, width, height);
        for &i in &region.texels {
            tried[i] = true;
        }
        let background = region.background(&out.residual, width, height);
        let Some(found) = sky.sun_of(&region.texels, &out.residual, background, peak, total) else {
            continue;
        };
        for &i in &region.texels {
            out.residual.texels[i] = background.map(|b| b as f32);
            luminance[i] = lum(out.residual.texels[i]);
        }
        let scaled = found.power.map(|p| p * f64::from(strength));
        let peak_power = scaled.iter().copied().fold(0.0f64, f64::max);
        out.suns.push(SunLight {
            direction: found.axis,
            half_angle: found.half_angle,
            strength: peak_power as f32,
            color: scaled.map(|p| (p / peak_power) as f32),
        });
        out.shares.push(found.share);
    }
    out
}

/// The brightest texel not yet tried, the last of equals (as `Iterator::max_by`).
fn brightest_untried(luminance: &[f64], tried: &[bool]) -> Option<usize> {
    let mut peak = None;
    for (i, &l) in luminance.iter().enumerate() {
        if !tried[i] && peak.is_none_or(|p: usize| l.total_cmp(&luminance[p]).is_ge()) {
            peak = Some(i);
        }
    }
    peak
}

/// A bright region of the map and the ring of texels around it, with masks of both that
/// are cleared where they were set when the next region is grown.
struct Region {
    texels: Vec<usize>,
    inside: Vec<bool>,
    ring: Vec<bool>,
    ring_texels: Vec<usize>,
}

impl Region {
    fn new(texels: usize) -> Self {
        Self { texels: Vec::new(), inside: vec![false; texels], ring: vec![false; texels], ring_texels: Vec::new() }
    }

    /// The region flood-filled from `peak` over the texels of luminance at least `floor`.
    fn grow(&mut self, peak: usize, floor: f64, luminance: &[f64], width: usize, height: usize) {
        for &i in &self.texels {
            self.inside[i] = false;
        }
        self.texels.clear();
        self.texels.push(peak);
        self.inside[peak] = true;
        let mut next = 0;
        while next < self.texels.len() {
            let i = self.texels[next];
            next += 1;
            for j in neighbours(i, width, height) {
                if !self.inside[j] && luminance[j] >= floor {
                    self.inside[j] = true;
                    self.texels.push(j);
                }
            }
        }
    }

    /// The sky behind the region: the mean radiance of `residual` over the texels around
    /// it.
    fn background(&mut self, residual: &EnvironmentMap, width: usize, height: usize) -> [f64; 3] {
        for &j in &self.ring_texels {
            self.ring[j] = false;
        }
        self.ring_texels.clear();
        let mut background = [0.0f64; 3];
        for &i in &self.texels {
            for j in neighbours(i, width, height) {
                if !self.inside[j] && !self.ring[j] {
                    self.ring[j] = true;
                    self.ring_texels.push(j);
                    for k in 0..3 {
                        background[k] += f64::from(residual.texels[j][k]);
                    }
                }
            }
        }
        let ring_count = self.ring_texels.len();
        background.map(|b| if ring_count > 0 { b / ring_count as f64 } else { 0.0 })
    }
}

/// A sun found in a region: its power per channel above the sky behind it, its axis and
/// half-angle, and its share of the map's luminous power.
struct FoundSun {
    power: [f64; 3],
    axis: [f64; 3],
    half_angle: f64,
    share: f64,
}

/// What the search reads of each texel of a map: its solid angle and direction.
struct SkyTexels {
    width: usize,
    solid_angle: Vec<f64>,
    rows: Vec<[f64; 2]>,
    columns: Vec<[f64; 2]>,
}

impl SkyTexels {
    fn of(width: usize, height: usize, map: &EnvironmentMap) -> Self {
        let solid_angle: Vec<f64> = (0..height).map(|r| map.texel_solid_angle(r)).collect();
        let (rows, columns) = direction_factors(width, height);
        Self { width, solid_angle, rows, columns }
    }

    fn direction(&self, i: usize) -> [f64; 3] {
        let ([sin_theta, cos_theta], [cos_phi, sin_phi]) = (self.rows[i / self.width], self.columns[i % self.width]);
        [sin_theta * cos_phi, sin_theta * sin_phi, cos_theta]
    }

    /// The sun `region` (grown from `peak`) holds above `background` in `residual`:
    /// `None` where it carries less than [`MIN_SUN_SHARE`] of `total` or reaches beyond
    /// [`MAX_SUN_RADIUS`] of its centre. Its half-angle is that of a uniform disk with the
    /// region's second moment about the centre, at least a texel's.
    fn sun_of(
        &self,
        region: &[usize],
        residual: &EnvironmentMap,
        background: [f64; 3],
        peak: usize,
        total: f64,
    ) -> Option<FoundSun> {
        let width = self.width;
        let mut power = [0.0f64; 3];
        let (mut centre, mut weight_sum) = ([0.0f64; 3], 0.0);
        for &i in region {
            let t = residual.texels[i];
            let above = [0, 1, 2].map(|k| (f64::from(t[k]) - background[k]).max(0.0) * self.solid_angle[i / width]);
            let weight = (0..3).map(|k| LUMINANCE[k] * above[k]).sum::<f64>();
            let d = self.direction(i);
            for k in 0..3 {
                power[k] += above[k];
                centre[k] += weight * d[k];
            }
            weight_sum += weight;
        }
        let share = weight_sum / total;
        let length = (centre[0] * centre[0] + centre[1] * centre[1] + centre[2] * centre[2]).sqrt();
        if !(share >= MIN_SUN_SHARE && length > 0.0) {
            return None;
        }
        let axis = centre.map(|c| c / length);
        let angle_to = |i: usize| {
            let d = self.direction(i);
            (d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]).clamp(-1.0, 1.0).acos()
        };
        if region.iter().any(|&i| angle_to(i) > MAX_SUN_RADIUS) {
            return None;
        }
        let second_moment = region
            .iter()
            .map(|&i| {
                let t = residual.texels[i];
                let above = (0..3)
                    .map(|k| LUMINANCE[k] * (f64::from(t[k]) - background[k]).max(0.0) * self.solid_angle[i / width])
                    .sum::<f64>();
                above * angle_to(i).powi(2)
            })
            .sum::<f64>()
            / weight_sum;
        let texel_radius = (self.solid_angle[peak / width] / std::f64::consts::PI).sqrt();
        let half_angle = (2.0 * second_moment).sqrt().max(texel_radius).min(std::f64::consts::FRAC_PI_2);
        Some(FoundSun { power, axis, half_angle, share })
    }
}

/// Per row, `[sin(theta), cos(theta)]`, and per column, `[cos(phi), sin(phi)]`, of the
/// texel centres of a `width` x `height` map, as [`equirectangular_to_direction`](crate::scene::light::equirectangular_to_direction) takes
/// them.
fn direction_factors(width: usize, height: usize) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let rows = (0..height)
        .map(|r| {
            let theta = -PI * (1.0 - (r as f64 + 0.5) / height as f64) + PI;
            [theta.sin(), theta.cos()]
        })
        .collect();
    let columns = (0..width)
        .map(|c| {
            let phi = -2.0 * PI * ((c as f64 + 0.5) / width as f64) + PI;
            [phi.cos(), phi.sin()]
        })
        .collect();
    (rows, columns)
}

/// The 8 neighbours of texel `i`, wrapping in azimuth and stopping at the poles' rows,
/// row by row from the one above, each row's from the column on the left.
#[inline]
fn neighbours(i: usize, width: usize, height: usize) -> impl Iterator<Item = usize> {
    let (c, r) = (i % width, i / width);
    let columns = [if c == 0 { width - 1 } else { c - 1 }, c, if c + 1 == width { 0 } else { c + 1 }];
    let mut found = [0usize; 8];
    let mut count = 0;
    for (dr, row) in [r.wrapping_sub(1), r, r + 1].into_iter().enumerate() {
        if row >= height {
            continue;
        }
        for (dc, &column) in columns.iter().enumerate() {
            if (dr, dc) != (1, 1) {
                found[count] = row * width + column;
                count += 1;
            }
        }
    }
    found.into_iter().take(count)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::light::direction_to_equirectangular;

    fn sky(width: usize, sun: Option<([f64; 3], f32)>) -> EnvironmentMap {
        let height = width / 2;
        let mut texels: Vec<[f32; 3]> = (0..width * height)
            .map(|i| {
                let up = 1.0 - (i / width) as f32 / height as f32;
                [0.3 + 0.5 * up, 0.4 + 0.4 * up, 0.8]
            })
            .collect();
        if let Some((d, radiance)) = sun {
            let [u, v] = direction_to_equirectangular(d);
            let (c, r) = ((u * width as f64) as usize, ((1.0 - v) * height as f64) as usize);
            texels[r * width + c] = [radiance, radiance * 0.9, radiance * 0.8];
            texels[r * width + (c + 1) % width] = [radiance * 0.5, radiance * 0.45, radiance * 0.4];
        }
        EnvironmentMap { file: "sky.exr".into(), width, height, texels }
    }

    fn power(map: &EnvironmentMap) -> [f64; 3] {
        let mut p = [0.0; 3];
        for (i, t) in map.texels.iter().enumerate() {
            for k in 0..3 {
                p[k] += f64::from(t[k]) * map.texel_solid_angle(i / map.width);
            }
        }
        p
    }

    /// A two-texel sun comes out where it is, with the map's power split exactly between
    /// it and the residual, and the residual no brighter than the sky around it.
    #[test]
    fn a_sun_is_extracted_and_power_is_kept() {
        let d: [f64; 3] = [0.5, -0.4, 0.6];
        let l = d.iter().map(|c| c * c).sum::<f64>().sqrt();
        let d = d.map(|c| c / l);
        let map = sky(512, Some((d, 5e4)));
        let split = extract_suns(&map, 2.0);
        assert_eq!(split.suns.len(), 1, "{:?}", split.suns);
        let sun = split.suns[0];
        let angle = (sun.direction[0] * d[0] + sun.direction[1] * d[1] + sun.direction[2] * d[2]).acos();
        assert!(angle < 0.01, "sun {:?} is {angle} rad from {d:?}", sun.direction);
        assert!(sun.half_angle < 0.02, "half-angle {}", sun.half_angle);
        assert!(split.shares[0] > 0.4, "share {}", split.shares[0]);
        let (before, after) = (power(&map), power(&split.residual));
        for k in 0..3 {
            let sun_power = f64::from(sun.strength * sun.color[k]) / 2.0;
            assert!((after[k] + sun_power - before[k]).abs() < 1e-6 * before[k], "channel {k}");
        }
        let brightest = split.residual.texels.iter().map(|t| t[0]).fold(0.0f32, f32::max);
        assert!(brightest <= 0.81, "residual peak {brightest}");
    }

    /// The texel directions from the row and column factors are
    /// `equirectangular_to_direction`'s at the texel centres, bit for bit; and the
    /// neighbours come in the order of rows then columns, wrapping in azimuth and stopping
    /// at the poles, on maps down to one texel wide (where a texel neighbours itself).
    #[test]
    fn directions_and_neighbours_are_the_texel_walk_of_the_decomposition() {
        use crate::scene::light::equirectangular_to_direction;
        for (width, height) in [(1, 1), (1, 3), (2, 2), (7, 5), (64, 32)] {
            let (rows, columns) = direction_factors(width, height);
            for i in 0..width * height {
                let (c, r) = (i % width, i / width);
                let ([sin_theta, cos_theta], [cos_phi, sin_phi]) = (rows[r], columns[c]);
                let expected = equirectangular_to_direction(
                    (c as f64 + 0.5) / width as f64,
                    1.0 - (r as f64 + 0.5) / height as f64,
                );
                assert_eq!([sin_theta * cos_phi, sin_theta * sin_phi, cos_theta], expected, "{width}x{height}, {i}");
                let mut walk = Vec::new();
                for dr in -1i64..=1 {
                    for dc in -1i64..=1 {
                        let row = r as i64 + dr;
                        if (dr, dc) != (0, 0) && (0..height as i64).contains(&row) {
                            walk.push(row as usize * width + (c as i64 + dc).rem_euclid(width as i64) as usize);
                        }
                    }
                }
                assert_eq!(neighbours(i, width, height).collect::<Vec<_>>(), walk, "{width}x{height}, texel {i}");
            }
        }
    }

    /// A light's decomposition is `extract_suns` of its map, with the residual at the
    /// light's strength; made once for consecutive calls on the same light, and anew for
    /// another; none for a light without a map.
    #[test]
    fn a_light_is_decomposed_once_for_consecutive_calls() {
        let d: [f64; 3] = [0.5, -0.4, 0.6];
        let l = d.iter().map(|c| c * c).sum::<f64>().sqrt();
        let light = Arc::new(Light::Environment { map: sky(128, Some((d.map(|c| c / l), 5e4))), strength: 2.0 });
        let Light::Environment { map, .. } = light.as_ref() else { unreachable!() };
        let direct = extract_suns(map, 2.0);
        let split = decomposition(&light).expect("a map");
        assert_eq!((split.suns.len(), &split.suns, &split.shares), (1, &direct.suns, &direct.shares));
        assert_eq!(split.residual, Light::Environment { map: direct.residual, strength: 2.0 });
        // The same decomposition again, unless another thread's light came between (the
        // cache holds one light; the plans of other tests use it too).
        let again = (0..100).any(|_| {
            let first = decomposition(&light).expect("a map");
            Arc::ptr_eq(&first, &decomposition(&light).expect("a map"))
        });
        assert!(again, "the light was decomposed again");
        let other = Arc::new(Light::Environment { map: sky(64, None), strength: 2.0 });
        assert!(decomposition(&other).expect("a map").suns.is_empty());
        assert!(decomposition(&Arc::new(Light::Constant([1.0; 3]))).is_none());
    }

    /// A smooth sky, and a bright but wide region, stay in SH.
    #[test]
    fn smooth_skies_keep_their_light() {
        assert!(extract_suns(&sky(256, None), 1.0).suns.is_empty());
        let mut wide = sky(256, None);
        for r in 20..50 {
            for c in 40..90 {
                wide.texels[r * 256 + c] = [200.0; 3];
            }
        }
        assert!(extract_suns(&wide, 1.0).suns.is_empty(), "a 40-degree bright patch is not a sun");
    }

    /// The residual's SH projection against the map it stands for: a bright region left
    /// in SH rings, the truncated projection dipping below zero across the sphere, and a
    /// window (`--light-window`) trades that ringing for blur while keeping the power.
    #[test]
    fn windowing_the_residual_limits_its_ringing() {
        use crate::shade::LightWindow;
        let order = 4;
        let mut wide = sky(256, None);
        for r in 20..50 {
            for c in 40..90 {
                wide.texels[r * 256 + c] = [200.0; 3];
            }
        }
        let residual = extract_suns(&wide, 1.0).residual;
        let projected = crate::scene::Light::Environment { map: residual, strength: 1.0 }.sh_coefficients(order);
        let lowest = |window: LightWindow| {
            let mut coefficients = projected.clone();
            window.apply(order, &mut coefficients);
            assert_eq!(coefficients[0], projected[0], "{window:?} keeps the power");
            let mut y = [0.0; 16];
            let mut lowest = f64::INFINITY;
            for i in 0..64 {
                for j in 0..128 {
                    let (theta, phi) =
                        (std::f64::consts::PI * (i as f64 + 0.5) / 64.0, std::f64::consts::TAU * j as f64 / 128.0);
                    let dir = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
                    crate::sh::eval_basis(order, dir, &mut y);
                    lowest = lowest.min((0..16).map(|k| y[k] * coefficients[k][0]).sum::<f64>());
                }
            }
            lowest / (projected[0][0] * crate::sh::exp::Y0)
        };
        let (none, lanczos, hann) =
            (lowest(LightWindow::None), lowest(LightWindow::Lanczos), lowest(LightWindow::Hann));
        println!("lowest value over the mean: none {none:.3}, lanczos {lanczos:.3}, hann {hann:.3}");
        assert!(none < -0.1, "the unwindowed projection rings: lowest {none} of the mean");
        assert!(lanczos > 0.2 * none && hann > 0.2 * none, "none {none}, lanczos {lanczos}, hann {hann}");
    }
}
