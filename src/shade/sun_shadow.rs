//! A sun's visibility from its shadow map ([`crate::scene::sun_shadow`]): the blocker
//! meshes' own silhouette, where the sphere proxies' caps only approximate it. The proxies
//! differ from the meshes by 14 to 58 % of their volume, and under a sharp sun a receiver
//! on the wrong side of a shadow edge is off by the sun's whole light; the map puts the
//! edges where the meshes put them, to a texel. The proxies still shade the environment
//! and the lamps without a map.
//!
//! # The march
//!
//! The map holds, texel by texel, the depths `Z` and `Zfar` below its plane of the first
//! and the last mesh surface along the axis, and the meshes are taken to fill the
//! interval between them (exact for a convex mesh; for a concave one, or two meshes one
//! above the other, the gap between counts as solid). A direction `w` of the sun's disk
//! ([`super::sun`]) from receiver `p` is blocked where its ray `p + t w` passes through
//! some texel's interval: walking the texels the ray crosses sideways (Amanatides and
//! Woo's traversal), from `t = 0` to where it rises above the map's shallowest surface, at
//! most [`MAX_STEPS`] of them, a texel blocks where the ray spans over it depths from
//! below its top surface to above its bottom one: `Z + bias < d(t0)` and `d(t1) < Zfar +
//! bias`, `[t0, t1]` the ray's stretch over the texel and `d(t) = d(p) - t (w . axis)` its
//! depth below the plane.
//!
//! - `bias = texel (1 + 2 min(tan theta, 8))`, `theta` the angle between the receiver's
//!   normal and the axis: a receiver on a lit mesh face is half a texel from its texel's
//!   centre, so up to half a texel times `tan theta` below the depth the map holds there.
//!   Lifting receivers along their normal as well (1.5 texels, the usual normal offset)
//!   was measured and not kept: it narrowed every shadow by the lift (`primitives` under a
//!   Sun lamp 0.0052 to 0.0055 against Cycles, the Sky Texture 0.0118 to 0.0136).
//! - Each direction is wholly blocked or wholly open (32 directions over the disk: the
//!   penumbra in steps of 1/32).
//! - Two tests end most receivers' march: a receiver inside its own texel's interval is
//!   blocked along every direction (every ray starts there); and one whose rays' whole
//!   footprint lies over texels whose `Z` is deeper than it (the minima of
//!   [`ShadowMapMarch::level`], a pyramid of 2 x 2 minima) sees the whole disk. The
//!   footprint's shallowest `Z` also ends the others' rays: none of its texels blocks a
//!   ray risen above it.
//!
//! The GPU reads the same levels from its tables (`shaders/disk.wgsl`, `shadow_blocked`).

use crate::scene::sun_shadow::{NOTHING_BELOW, SAME_SUN_RADIANS};
use crate::scene::SunShadowMap;
use crate::vector::dot;
use std::sync::Arc;

/// Most texels one direction's ray crosses (a ray that drifts farther sideways is taken
/// as clear beyond them).
pub const MAX_STEPS: usize = 64;

/// Most levels of minima a map has: one of [`crate::scene::MAX_IMAGE_SIDE`] texels a side
/// halves to one texel in 15.
pub const MINIMA_LEVELS: usize = 15;

/// A shadow map with its pyramid of minima, ready to march.
#[derive(Debug)]
pub struct ShadowMapMarch {
    pub map: Arc<SunShadowMap>,
    /// Levels 1 and on: each the minimum over 2 x 2 texels of the one before (an odd last
    /// column or row alone), down to one texel; level 0 is the map's `Z` itself
    /// ([`Self::level`]).
    coarser: Vec<MinLevel>,
}

/// One level of the pyramid of minima ([`ShadowMapMarch::level`]).
#[derive(Clone, Debug)]
pub struct MinLevel {
    pub columns: usize,
    pub rows: usize,
    pub depths: Vec<f32>,
}

/// A receiver's place in a map's frame.
#[derive(Clone, Copy, Debug)]
struct InMap {
    /// Along `right` and `up` from the origin, and depth below the plane.
    across: [f64; 2],
    depth: f64,
    bias: f64,
}

impl ShadowMapMarch {
    pub fn new(map: Arc<SunShadowMap>) -> Self {
        let mut coarser: Vec<MinLevel> = Vec::new();
        let mut last = (map.columns, map.rows, &map.depths[..]);
        while last.0 > 1 || last.1 > 1 {
            let (columns, rows) = (last.0.div_ceil(2), last.1.div_ceil(2));
            let mut depths = vec![f32::INFINITY; columns * rows];
            for y in 0..last.1 {
                for x in 0..last.0 {
                    let at = &mut depths[(y / 2) * columns + x / 2];
                    *at = at.min(last.2[y * last.0 + x]);
                }
            }
            coarser.push(MinLevel { columns, rows, depths });
            let level = coarser.last().expect("just pushed");
            last = (level.columns, level.rows, &level.depths[..]);
        }
        Self { map, coarser }
    }

    /// How many levels the pyramid has, level 0 the map's `Z`.
    pub fn level_count(&self) -> usize {
        1 + self.coarser.len()
    }

    /// Level `k`'s columns, rows and minima.
    pub fn level(&self, k: usize) -> (usize, usize, &[f32]) {
        match k {
            0 => (self.map.columns, self.map.rows, &self.map.depths),
            k => {
                let l = &self.coarser[k - 1];
                (l.columns, l.rows, &l.depths)
            }
        }
    }

    /// The shallowest surface in the map.
    pub fn shallowest(&self) -> f32 {
        let (_, _, top) = self.level(self.level_count() - 1);
        top.first().copied().unwrap_or(NOTHING_BELOW)
    }

    /// Where `p` (unit normal `n`) lies in the map's frame.
    fn place(&self, p: [f64; 3], n: [f64; 3]) -> InMap {
        let m = &self.map;
        let rel = [0, 1, 2].map(|k| p[k] - m.origin[k]);
        let cos = dot(n, m.axis).abs().max(1e-6);
        let tan = ((1.0 - cos * cos).max(0.0).sqrt() / cos).min(8.0);
        InMap {
            across: [dot(rel, m.right), dot(rel, m.up)],
            depth: -dot(rel, m.axis),
            bias: m.texel() * (1.0 + 2.0 * tan),
        }
    }

    /// Level 0's texel under `across`, `None` off the map.
    fn texel_under(&self, across: [f64; 2]) -> Option<(usize, usize)> {
        let [x, y] = self.texel_coordinates(across).map(f64::floor);
        let inside = x >= 0.0 && y >= 0.0 && x < self.map.columns as f64 && y < self.map.rows as f64;
        inside.then_some((x as usize, y as usize))
    }

    /// Whether the depths from `deep` up to `shallow` meet the meshes' interval at
    /// `texel`, its top lowered and its bottom lowered by `bias`.
    fn meets(&self, (x, y): (usize, usize), deep: f64, shallow: f64, bias: f64) -> bool {
        let at = y * self.map.columns + x;
        f64::from(self.map.depths[at]) < deep - bias && shallow < f64::from(self.map.far_depths[at]) + bias
    }

    /// The shallowest depth over the texels that the square of half-side `half` about
    /// `across` touches (from the coarsest level whose 2 x 2 texels cover it), `None`
    /// where it lies wholly off the map.
    fn shallowest_around(&self, across: [f64; 2], half: f64) -> Option<f64> {
        let m = &self.map;
        let [x0, y0] = self.texel_coordinates([across[0] - half, across[1] + half]).map(f64::floor);
        let [x1, y1] = self.texel_coordinates([across[0] + half, across[1] - half]).map(f64::floor);
        if x1 < 0.0 || y1 < 0.0 || x0 >= m.columns as f64 || y0 >= m.rows as f64 {
            return None;
        }
        let clamp = |v: f64, n: usize| v.clamp(0.0, (n - 1) as f64) as usize;
        let (mut x0, mut x1) = (clamp(x0, m.columns), clamp(x1, m.columns));
        let (mut y0, mut y1) = (clamp(y0, m.rows), clamp(y1, m.rows));
        let mut level = 0;
        while x1 - x0 > 1 || y1 - y0 > 1 {
            (x0, x1, y0, y1) = (x0 / 2, x1 / 2, y0 / 2, y1 / 2);
            level += 1;
        }
        let (columns, _, minima) = self.level(level);
        let at = |x: usize, y: usize| minima[y * columns + x];
        Some(f64::from(at(x0, y0).min(at(x1, y0)).min(at(x0, y1)).min(at(x1, y1))))
    }

    /// `across` in level 0's texels, fractional: texel `(i, j)` spans `[i, i + 1) x [j, j + 1)`.
    fn texel_coordinates(&self, across: [f64; 2]) -> [f64; 2] {
        let m = &self.map;
        [(across[0] / m.size[0] + 0.5) * m.columns as f64, (0.5 - across[1] / m.size[1]) * m.rows as f64]
    }

    /// Whether the ray from `from` (texel coordinates) moving `velocity` texels per unit
    /// `t`, at depth `depth(t)`, meets the meshes' interval of a texel it crosses before
    /// `t = end`: the texels walked one boundary at a time (Amanatides and Woo's
    /// traversal), each taking the depths the ray has over it, at most [`MAX_STEPS`].
    fn ray_meets(&self, from: [f64; 2], velocity: [f64; 2], end: f64, depth: impl Fn(f64) -> f64, bias: f64) -> bool {
        let m = &self.map;
        let mut cell = [from[0].floor(), from[1].floor()];
        let step = velocity.map(|v| if v > 0.0 { 1.0 } else { -1.0 });
        let crossing = |k: usize, cell: f64| {
            let v = velocity[k];
            match v {
                v if v > 0.0 => (cell + 1.0 - from[k]) / v,
                v if v < 0.0 => (cell - from[k]) / v,
                _ => f64::INFINITY,
            }
        };
        let mut next = [crossing(0, cell[0]), crossing(1, cell[1])];
        let mut enter = 0.0;
        for _ in 0..MAX_STEPS {
            let exit = next[0].min(next[1]).min(end);
            let inside = cell[0] >= 0.0 && cell[1] >= 0.0 && cell[0] < m.columns as f64 && cell[1] < m.rows as f64;
            if inside && self.meets((cell[0] as usize, cell[1] as usize), depth(enter), depth(exit), bias) {
                return true;
            }
            if exit >= end {
                return false;
            }
            let k = usize::from(next[1] < next[0]);
            cell[k] += step[k];
            next[k] = crossing(k, cell[k]);
            enter = exit;
        }
        false
    }

    /// Which of `directions` (unit, drifting sideways from the map's axis by at most
    /// `drift` per unit of depth: [`drift_per_depth`]) the meshes block from `p` with unit
    /// normal `n`: `None` where none is, so that the disk stays open.
    pub fn blocked<const K: usize>(
        &self,
        directions: &[[f64; 3]; K],
        drift: f64,
        p: [f64; 3],
        n: [f64; 3],
    ) -> Option<[bool; K]> {
        let at = self.place(p, n);
        let top = f64::from(self.shallowest());
        let clear_below = at.depth - at.bias;
        if clear_below <= top {
            return None;
        }
        if self.texel_under(at.across).is_some_and(|texel| self.meets(texel, at.depth, at.depth, at.bias)) {
            return Some([true; K]);
        }
        // Every ray stays within the footprint of a ray that rises to the map's shallowest
        // surface, and no texel there blocks it once it rises above their shallowest.
        let nearby = match self.shallowest_around(at.across, (clear_below - top) * drift) {
            Some(shallowest) if shallowest < clear_below => shallowest,
            _ => return None,
        };
        let reach = clear_below - nearby;
        let m = &self.map;
        let from = self.texel_coordinates(at.across);
        let mut blocked = [false; K];
        for (w, b) in directions.iter().zip(&mut blocked) {
            let along = dot(*w, m.axis);
            if along > 0.5 {
                let velocity = [dot(*w, m.right) / m.texel(), -dot(*w, m.up) / m.texel()];
                *b = self.ray_meets(from, velocity, reach / along, |t| at.depth - t * along, at.bias);
            }
        }
        blocked.iter().any(|&b| b).then_some(blocked)
    }
}

/// How far the rays of a sun's disk of half-angle `half_angle` drift sideways per unit
/// of depth in the map that serves it: the disk's directions lie within `half_angle` of
/// the sun, the sun within [`SAME_SUN_RADIANS`] of the map's axis.
pub fn drift_per_depth(half_angle: f64) -> f64 {
    (half_angle + SAME_SUN_RADIANS).min(1.0).tan()
}

/// A frame's shadow maps, each ready to march.
#[derive(Debug, Default)]
pub struct SunShadows {
    pub maps: Vec<ShadowMapMarch>,
}

impl SunShadows {
    pub fn new(maps: &[Arc<SunShadowMap>]) -> Self {
        Self { maps: maps.iter().cloned().map(ShadowMapMarch::new).collect() }
    }

    /// The map of the sun towards unit `direction`, if the frame has one.
    pub fn of_sun(&self, direction: [f64; 3]) -> Option<&ShadowMapMarch> {
        self.maps.iter().find(|m| m.map.serves(direction))
    }

    pub fn is_empty(&self) -> bool {
        self.maps.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Sphere;
    use crate::shade::blocker_tree::BlockerTree;
    use crate::shade::sun::{Casters, DiskDirections, DiskHorizon, Planes};
    use crate::synth::{sun_shadow_map, Object, Shape};
    use crate::vector::{cross, normalize};

    const CENTER: [f64; 3] = [0.0, 0.0, 1.0];
    const RADIUS: f64 = 0.5;

    fn sun() -> DiskDirections {
        DiskDirections::new(normalize([0.3, -0.2, 1.0]), 2f64.to_radians())
    }

    fn march(long: usize) -> ShadowMapMarch {
        march_along(sun().axis, long)
    }

    fn march_along(axis: [f64; 3], long: usize) -> ShadowMapMarch {
        let sphere = Object { shape: Shape::Sphere { center: CENTER, radius: RADIUS }, material: 1 };
        let map = sun_shadow_map(&[sphere], axis, long).expect("a sphere");
        ShadowMapMarch::new(Arc::new(map))
    }

    /// The sun's axis turned by `degrees` about the horizontal axis across it.
    fn turned_axis(degrees: f64) -> [f64; 3] {
        let axis = sun().axis;
        let across = normalize(cross(axis, [0.0, 0.0, 1.0]));
        let toward = cross(across, axis);
        let (s, c) = degrees.to_radians().sin_cos();
        [0, 1, 2].map(|k| c * axis[k] + s * toward[k])
    }

    fn mean_visibility(
        disk: &DiskDirections,
        map: Option<&ShadowMapMarch>,
        tree: Option<&BlockerTree>,
        p: [f64; 3],
        n: [f64; 3],
    ) -> f64 {
        let planes = Planes { tangent: true, ground: None };
        let casters = match (map, tree) {
            (Some(map), _) => Casters::Map(map),
            (None, tree) => Casters::from(tree),
        };
        let seen = disk.seen_against(casters, DiskHorizon::None, planes, p, n, 0);
        seen.visibility().iter().sum::<f64>() / crate::shade::sun::DISK_DIRECTIONS as f64
    }

    /// A sphere's map shades a sun 4 degrees wide as the sphere's exact cap does, over a
    /// floor across its shadow and penumbra: the map's directions are blocked or not, the
    /// cap's patches partly, so they differ by a share of a direction at most in the
    /// penumbra. So does a map rendered along an axis 0.9 degrees off the sun's (an
    /// environment map's sun, found by the exporter and by logsh apart), which the map
    /// serves; one 1.1 degrees off does not.
    #[test]
    fn a_spheres_map_shades_the_sun_as_the_sphere_does() {
        assert!(march_along(turned_axis(0.9), 64).map.serves(sun().axis));
        assert!(!march_along(turned_axis(1.1), 64).map.serves(sun().axis));
        for offset in [0.0, 0.9] {
            shades_as_the_sphere(&march_along(turned_axis(offset), 512), offset);
        }
    }

    fn shades_as_the_sphere(march: &ShadowMapMarch, offset: f64) {
        let disk = sun();
        let tree = BlockerTree::new(&[Sphere::new(CENTER, RADIUS)], 0.0);
        let (mut sum, mut worst, mut count, mut shaded) = (0.0, 0.0f64, 0, 0);
        for i in 0..80 {
            for j in 0..80 {
                let p = [-1.5 + 3.0 * i as f64 / 79.0, -1.5 + 3.0 * j as f64 / 79.0, 0.0];
                let by_map = mean_visibility(&disk, Some(march), None, p, [0.0, 0.0, 1.0]);
                let by_cap = mean_visibility(&disk, None, Some(&tree), p, [0.0, 0.0, 1.0]);
                let d = (by_map - by_cap).abs();
                sum += d;
                worst = worst.max(d);
                count += 1;
                shaded += usize::from(by_cap < 1.0);
            }
        }
        println!(
            "map {offset} degrees off the sun: {shaded} of {count} receivers shaded; map against cap: mean {:.2e}, \
             worst {worst:.3}",
            sum / count as f64
        );
        assert!(shaded > 500, "the floor must cross the shadow: {shaded}");
        assert!(sum / count as f64 <= 2e-3 && worst <= 0.08, "mean {}, worst {worst}", sum / count as f64);
    }

    /// The sphere's own sunlit side is not shadowed by its own map (the bias), and a
    /// receiver under it sees none of the sun.
    #[test]
    fn a_lit_surface_is_not_shadowed_by_itself() {
        let (disk, march) = (sun(), march(256));
        let mut lit = 0;
        for k in 0..400 {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / 400.0;
            let phi = k as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let n = [(1.0 - z * z).sqrt() * phi.cos(), (1.0 - z * z).sqrt() * phi.sin(), z];
            if dot(n, disk.axis) < 0.1 {
                continue;
            }
            let p = [0, 1, 2].map(|k| CENTER[k] + RADIUS * n[k]);
            let by_map = mean_visibility(&disk, Some(&march), None, p, n);
            let open = mean_visibility(&disk, None, None, p, n);
            assert_eq!(by_map, open, "normal {n:?}");
            lit += 1;
        }
        assert!(lit > 150, "{lit}");
        let under = [0, 1, 2].map(|k| CENTER[k] - 1.5 * disk.axis[k]);
        assert_eq!(mean_visibility(&disk, Some(&march), None, under, disk.axis), 0.0);
    }
}
