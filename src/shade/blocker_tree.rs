//! The sphere blockers of a frame as a bounding-sphere hierarchy, so that a receiver's
//! cost grows with the blockers near it rather than with all of them: distant clusters
//! are seen as one cap (Ren et al. 2006, "Real-time Soft Shadows in Dynamic Scenes using
//! Spherical Harmonic Exponentiation", Section 5's sphere hierarchy; paper 000's future
//! work), clusters wholly behind the receiver's tangent plane are skipped, and caps too
//! small to matter are dropped.
//!
//! The tree is flattened depth first with a skip link per node (the node after its
//! subtree), so both executors walk it without a stack: the CPU kernel here
//! ([`BlockerTree::visit`]) and the WGSL pass (`shaders/logsh.wgsl`, `visit_blockers`),
//! from the same node array.
//!
//! What a receiver at `p` with normal `n` does at a node of bounding sphere `(c, R)`,
//! `d = |c - p|`:
//!
//! - `n . (c - p) < -R (1 - BEHIND_TOLERANCE)`: every centre below lies behind the
//!   tangent plane, where each sphere is culled anyway (paper 000, end of Section 4.2):
//!   skipped ([`BEHIND_TOLERANCE`] keeps a sphere touching the plane from behind out on
//!   both executors).
//! - a leaf: its sphere is seen as it is.
//! - `d > R` and `R <= cluster_ratio d` (the node spans at most about `2 cluster_ratio`
//!   radians): one cap, of the node's equivalent sphere: centred at the children's
//!   centres weighted by `r^2`, radius `min(sqrt(sum r^2), R)`, which keeps the summed
//!   solid angle `pi r^2 / d^2` of disjoint distant spheres and never exceeds the cluster's
//!   bounds (its members' overlap is then counted once, not once per member). Dropped
//!   instead when that radius is below [`NEGLIGIBLE_RATIO`] `d`.
//! - otherwise: its children.
//!
//! `cluster_ratio = 0` merges nothing: every sphere in front of the tangent plane is
//! seen, as without the tree.

use crate::gpu_layout::GpuBlockerNode;
use crate::logsh::own_sphere_holds;
use crate::scene::Sphere;
use crate::vector::{cross, dot, normalize};
use std::cell::Cell;
use std::ops::ControlFlow;

/// A cap whose sphere's radius is below this fraction of its distance (solid angle below
/// `pi 0.004^2 = 5e-5` sr) is dropped when it is a cluster's: it would change an open
/// receiver's diffuse light by less than 2e-5 at the default epsilon.
pub const NEGLIGIBLE_RATIO: f64 = 0.004;

/// A subtree is behind the receiver's tangent plane when its bounds rise above the plane
/// by less than this fraction of their radius. A receiver on a sphere's surface, the
/// sphere's centre straight behind it along the normal, sits on that boundary exactly:
/// f64 and f32 rounding then decided differently whether the sphere was seen, and a
/// disk test (a sun's, a sharp lobe's core) took it for the hemisphere behind the plane.
/// What rises less than this above the plane blocks only a sliver along the horizon.
pub const BEHIND_TOLERANCE: f64 = 1e-4;

pub use crate::scene::camera::MAX_BLOCKERS;

/// One node of the flattened tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockerNode {
    /// Bounding sphere of the subtree (for a leaf, its sphere).
    pub bounds: Sphere,
    /// The subtree seen from afar as one sphere (for a leaf, its sphere).
    pub equivalent: Sphere,
    /// The share of the equivalent sphere's solid angle that is its own
    /// ([`overlap_shares`]): below 1 for a leaf whose object's spheres overlap, 1 for a
    /// cluster, whose equivalent already counts its members' overlap once.
    pub share: f64,
    /// Index of the node after this subtree.
    pub skip: u32,
    pub leaf: bool,
}

/// The hierarchy of one frame's spheres.
#[derive(Clone, Debug, Default)]
pub struct BlockerTree {
    pub nodes: Vec<BlockerNode>,
    /// Ratio of a cluster's bounding radius to its distance below which it is one cap.
    pub cluster_ratio: f64,
    /// The same nodes in f32, as the WGSL pass and the CPU's packets walk them.
    f32_nodes: Vec<GpuBlockerNode>,
}

impl BlockerTree {
    /// Builds the tree of `spheres` by median splits along the longest axis of their
    /// centres (`O(N log^2 N)`). Spheres of radius 0 block nothing and are left out.
    pub fn new(spheres: &[Sphere], cluster_ratio: f64) -> Self {
        let blocking: Vec<Sphere> = spheres.iter().copied().filter(|s| s.radius > 0.0).collect();
        let mut items: Vec<(Sphere, f64)> = blocking.iter().copied().zip(overlap_shares(&blocking)).collect();
        let mut nodes = Vec::with_capacity(2 * items.len());
        if !items.is_empty() {
            build(&mut items, &mut nodes);
        }
        let vec4 = |s: &Sphere| [s.center[0], s.center[1], s.center[2], s.radius].map(|v| v as f32);
        let f32_nodes = nodes
            .iter()
            .map(|node| GpuBlockerNode {
                bounds: vec4(&node.bounds),
                equivalent: vec4(&node.equivalent),
                skip: node.skip,
                leaf: node.leaf as u32,
                object: node.equivalent.object,
                share: node.share as f32,
            })
            .collect();
        Self { nodes, cluster_ratio, f32_nodes }
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The nodes in f32, in the same order: what the GPU pass uploads and the CPU's
    /// packets walk ([`super::cap_packet`]).
    pub fn f32_nodes(&self) -> &[GpuBlockerNode] {
        &self.f32_nodes
    }

    /// Calls `see` with every sphere (or cluster's equivalent sphere) that a receiver of
    /// object `object` at `p` with unit normal `n` sees (module doc), and its share of its
    /// solid angle ([`BlockerNode::share`]). The receiver's own spheres that hold it are
    /// not seen ([`own_sphere_holds`]).
    pub fn visit(&self, p: [f64; 3], n: [f64; 3], object: u32, see: impl FnMut(&Sphere, f64)) {
        self.walk(p, n, object, see, |node, d| {
            if node.leaf {
                return Step::Enter;
            }
            let r = node.bounds.radius;
            let distance = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if !(distance > r && r <= self.cluster_ratio * distance) {
                return Step::Enter;
            }
            let e = &node.equivalent;
            let q = [e.center[0] - p[0], e.center[1] - p[1], e.center[2] - p[2]];
            if e.radius >= NEGLIGIBLE_RATIO * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt() {
                Step::Cluster
            } else {
                Step::Skip
            }
        });
    }

    /// Calls `see` with every sphere that may block some direction of the cone of unit
    /// axis `axis` from `p` (a sun's disk), `cone` the sine and cosine of its half-angle
    /// (a disk's own, computed once per sun), never a cluster:
    /// sharp lights need the spheres themselves. A subtree is skipped when its bounds lie
    /// wholly behind the tangent plane of `n` or wholly outside the cone. The receiver's own
    /// spheres follow the same rule as [`Self::visit`]; once `see` breaks (the disk
    /// wholly covered), the rest are skipped. Inlined into its callers, where the compiler
    /// had stopped inlining it (its cost: docs/performance-log.md, "Several Sun lamps").
    #[inline(always)]
    pub fn visit_cone(
        &self,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
        axis: [f64; 3],
        cone: [f64; 2],
        mut see: impl FnMut(&Sphere) -> ControlFlow<()>,
    ) {
        let done = Cell::new(false);
        let see = |sphere: &Sphere, _share: f64| {
            if see(sphere).is_break() {
                done.set(true);
            }
        };
        self.walk(p, n, object, see, |node, d| {
            // A margin that keeps rounding from culling a grazing subtree.
            if done.get() || outside_cone(d, node.bounds.radius, axis, cone, 1e-9) {
                Step::Skip
            } else {
                Step::Enter
            }
        });
    }

    /// Whether a sphere may reach the cone of unit axis `axis` (`cone` the sine and cosine
    /// of its half-angle, as [`Self::visit_cone`] takes them) from some receiver within
    /// `spread` of `q`: where not, [`Self::visit_cone`] sees none from any of them. The
    /// directions from a receiver `p` to a ball `(c, r)` lie among those from `q` to `(c,
    /// r + |p - q|)`, so a subtree outside the cone from `q`, its bounds grown by
    /// `spread`, is outside it from every such receiver; the margin, 1e-6 of the distance
    /// where `visit_cone` keeps 1e-9, is far above the rounding of either test.
    pub fn cone_may_reach(&self, q: [f64; 3], spread: f64, axis: [f64; 3], cone: [f64; 2]) -> bool {
        let mut i = 0;
        while i < self.nodes.len() {
            let node = &self.nodes[i];
            let c = node.bounds.center;
            let d = [c[0] - q[0], c[1] - q[1], c[2] - q[2]];
            match (outside_cone(d, node.bounds.radius + spread, axis, cone, 1e-6), node.leaf) {
                (true, _) => i = node.skip as usize,
                (false, true) => return true,
                (false, false) => i += 1,
            }
        }
        false
    }

    /// The stackless walk both visits share: subtrees wholly behind the tangent plane of
    /// `n` are skipped; `step` decides for every other node, given `d = centre - p` of its
    /// bounds; a leaf entered is seen unless it is the receiver's own sphere holding it.
    fn walk(
        &self,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
        mut see: impl FnMut(&Sphere, f64),
        mut step: impl FnMut(&BlockerNode, [f64; 3]) -> Step,
    ) {
        let mut i = 0;
        while i < self.nodes.len() {
            let node = &self.nodes[i];
            let next = node.skip as usize;
            let c = node.bounds.center;
            let d = [c[0] - p[0], c[1] - p[1], c[2] - p[2]];
            if d[0] * n[0] + d[1] * n[1] + d[2] * n[2] < -node.bounds.radius * (1.0 - BEHIND_TOLERANCE) {
                i = next;
                continue;
            }
            match step(node, d) {
                Step::Skip => i = next,
                Step::Cluster => {
                    see(&node.equivalent, node.share);
                    i = next;
                }
                Step::Enter if node.leaf => {
                    let s = &node.equivalent;
                    if !(object != 0 && s.object == object && own_sphere_holds(p, s.center, s.radius)) {
                        see(s, node.share);
                    }
                    i = next;
                }
                Step::Enter => i += 1,
            }
        }
    }
}

/// Whether a ball of radius `r` whose centre lies `d` from the apex is wholly outside the
/// cone of unit axis `axis` (`[sin_half, cos_half]` its half-angle's sine and cosine): the
/// angle to the centre exceeds the half-angle plus the ball's own angular radius `beta =
/// asin(r / |d|)`, compared by cosines while that sum is below pi (its sine positive), all
/// times `|d|`, by more than `margin (sqrt(|d|^2 - r^2) + r)`.
#[inline(always)]
fn outside_cone(d: [f64; 3], r: f64, axis: [f64; 3], [sin_half, cos_half]: [f64; 2], margin: f64) -> bool {
    let squared = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    squared > r * r && {
        let along = d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2];
        let tangent = (squared - r * r).sqrt();
        let sin_sum = sin_half * tangent + cos_half * r;
        let cos_sum = cos_half * tangent - sin_half * r;
        sin_sum > 0.0 && along < cos_sum - margin * (tangent + r)
    }
}

/// What a walk does at a node in front of the tangent plane.
enum Step {
    /// Skip its subtree.
    Skip,
    /// See the subtree as its equivalent sphere.
    Cluster,
    /// A leaf: see its sphere; an inner node: go down into it.
    Enter,
}

/// Appends the subtree of `items` (each sphere with its [`overlap_shares`] entry) in
/// depth-first order; returns its root's index.
fn build(items: &mut [(Sphere, f64)], nodes: &mut Vec<BlockerNode>) -> usize {
    let index = nodes.len();
    if let [(sphere, share)] = *items {
        nodes.push(BlockerNode { bounds: sphere, equivalent: sphere, share, skip: index as u32 + 1, leaf: true });
        return index;
    }
    let first = items[0].0;
    nodes.push(BlockerNode { bounds: first, equivalent: first, share: 1.0, skip: 0, leaf: false });
    let (lo, hi) = centre_bounds(items);
    let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).expect("three axes");
    let middle = items.len() / 2;
    items.select_nth_unstable_by(middle, |a, b| a.0.center[axis].total_cmp(&b.0.center[axis]));
    let (left, right) = items.split_at_mut(middle);
    let a = build(left, nodes);
    let b = build(right, nodes);
    let bounds = enclosing(&nodes[a].bounds, &nodes[b].bounds);
    let equivalent = combined(&nodes[a], &nodes[b], bounds.radius);
    nodes[index] = BlockerNode { bounds, equivalent, share: 1.0, skip: nodes.len() as u32, leaf: false };
    index
}

fn centre_bounds(items: &[(Sphere, f64)]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (s, _) in items {
        for k in 0..3 {
            lo[k] = lo[k].min(s.center[k]);
            hi[k] = hi[k].max(s.center[k]);
        }
    }
    (lo, hi)
}

/// The smallest sphere holding spheres `a` and `b`.
fn enclosing(a: &Sphere, b: &Sphere) -> Sphere {
    let d = [b.center[0] - a.center[0], b.center[1] - a.center[1], b.center[2] - a.center[2]];
    let distance = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let object = if a.object == b.object { a.object } else { 0 };
    if distance + b.radius <= a.radius {
        return Sphere { object, ..*a };
    }
    if distance + a.radius <= b.radius {
        return Sphere { object, ..*b };
    }
    let radius = 0.5 * (distance + a.radius + b.radius);
    let t = (radius - a.radius) / distance;
    let center = [0, 1, 2].map(|k| a.center[k] + t * d[k]);
    Sphere { center, radius, object }
}

/// The equivalent sphere of two subtrees (module doc), at most `bound` in radius: each
/// sphere weighs by its own solid angle, its radius squared times its share.
fn combined(a: &BlockerNode, b: &BlockerNode, bound: f64) -> Sphere {
    let (a, wa) = (&a.equivalent, a.share * a.equivalent.radius * a.equivalent.radius);
    let (b, wb) = (&b.equivalent, b.share * b.equivalent.radius * b.equivalent.radius);
    let total = wa + wb;
    let center = [0, 1, 2].map(|k| (wa * a.center[k] + wb * b.center[k]) / total);
    let object = if a.object == b.object { a.object } else { 0 };
    Sphere { center, radius: total.sqrt().min(bound), object }
}

/// Directions of projection over which [`overlap_shares`] averages (a hemisphere holds
/// them all: a projection along `-u` is the mirror image of one along `u`).
const SHARE_DIRECTIONS: usize = 16;

/// Cells along each side of the square an object's spheres are projected onto.
const SHARE_GRID: usize = 48;

/// Each sphere's share of its own solid angle: for the spheres of one object (`object !=
/// 0`), the area of the union of their silhouettes over the sum of their areas, averaged
/// over [`SHARE_DIRECTIONS`] parallel projections; 1 for a sphere alone and for those of
/// no object.
///
/// A mesh's proxies overlap (a torus is 14 spheres, each reaching into the next), and
/// log visibilities add: where the caps are narrow enough that `exp` is linear in their
/// depth, each takes its own solid angle, so the overlap takes twice its share.
/// Measured on `primitives.py` against the reference renderer (exact visibility of the
/// same spheres), the floor around objects of 4 to 14 spheres came out 2.8 to 3.8 % too
/// dark, and around a single sphere 1.4 to 3.7 % too bright. The kernel scales each
/// narrow cap's depth by this share ([`super::fitted_depth::overlapped_depth`]). Estimated
/// on a grid of `SHARE_GRID^2` cells per projection: within about 2 % for a pair of
/// equal spheres half overlapping (the unit test).
pub fn overlap_shares(spheres: &[Sphere]) -> Vec<f64> {
    let mut shares = vec![1.0; spheres.len()];
    let mut by_object: std::collections::BTreeMap<u32, Vec<usize>> = std::collections::BTreeMap::new();
    for (i, s) in spheres.iter().enumerate() {
        if s.object != 0 {
            by_object.entry(s.object).or_default().push(i);
        }
    }
    for members in by_object.values().filter(|m| m.len() > 1) {
        let share = union_share(&members.iter().map(|&i| spheres[i]).collect::<Vec<_>>());
        for &i in members {
            shares[i] = share;
        }
    }
    shares
}

/// The mean over [`SHARE_DIRECTIONS`] projections of the union of the spheres' disks
/// over the sum of their areas, in `(0, 1]`.
fn union_share(spheres: &[Sphere]) -> f64 {
    let area: f64 = spheres.iter().map(|s| std::f64::consts::PI * s.radius * s.radius).sum();
    let mut total = 0.0;
    let mut covered = vec![false; SHARE_GRID * SHARE_GRID];
    for k in 0..SHARE_DIRECTIONS {
        // A Fibonacci spiral over the upper hemisphere.
        let z = 1.0 - (k as f64 + 0.5) / SHARE_DIRECTIONS as f64;
        let phi = k as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let w = [(1.0 - z * z).sqrt() * phi.cos(), (1.0 - z * z).sqrt() * phi.sin(), z];
        let helper = if w[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
        let u = normalize(cross(helper, w));
        let v = cross(w, u);
        let disks: Vec<[f64; 3]> = spheres.iter().map(|s| [dot(s.center, u), dot(s.center, v), s.radius]).collect();
        let lo = [0, 1].map(|a| disks.iter().map(|d| d[a] - d[2]).fold(f64::INFINITY, f64::min));
        let hi = [0, 1].map(|a| disks.iter().map(|d| d[a] + d[2]).fold(f64::NEG_INFINITY, f64::max));
        let cell = (hi[0] - lo[0]).max(hi[1] - lo[1]) / SHARE_GRID as f64;
        covered.fill(false);
        for d in &disks {
            let range = |a: usize| {
                let first = ((d[a] - d[2] - lo[a]) / cell).floor().max(0.0) as usize;
                let last = (((d[a] + d[2] - lo[a]) / cell).ceil() as usize).min(SHARE_GRID);
                first..last
            };
            for row in range(1) {
                let y = lo[1] + (row as f64 + 0.5) * cell - d[1];
                for column in range(0) {
                    let x = lo[0] + (column as f64 + 0.5) * cell - d[0];
                    if x * x + y * y <= d[2] * d[2] {
                        covered[row * SHARE_GRID + column] = true;
                    }
                }
            }
        }
        let union = covered.iter().filter(|&&c| c).count() as f64 * cell * cell;
        total += union / area;
    }
    (total / SHARE_DIRECTIONS as f64).clamp(f64::MIN_POSITIVE, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(count: usize) -> Vec<Sphere> {
        let mut rng = crate::logsh::training::SplitMix(0x2545_f491_4f6c_dd1d);
        let mut next = move || rng.next();
        (0..count).map(|_| Sphere::new([next() * 4.0 - 2.0, next() * 4.0 - 2.0, 1.0 + next()], 0.02)).collect()
    }

    /// Where [`BlockerTree::cone_may_reach`] says no sphere can reach a cone from a ball of
    /// receivers, [`BlockerTree::visit_cone`] sees none from any point of the ball, whatever
    /// its normal: 40 spheres 0.05 to 0.3 wide, cones 0.5 to 10 deg wide at four
    /// elevations, balls 0.01 to 1 wide over the ground, 48 points each (a third of them
    /// on the ball's surface). Both answers occur often, and a ball whose spread is taken
    /// for 0 fails.
    #[test]
    fn a_cone_no_sphere_can_reach_from_a_ball_is_reached_from_none_of_its_points() {
        let mut rng = crate::logsh::training::SplitMix(0x9e37_79b9_7f4a_7c15);
        let mut next = move || rng.next();
        let spheres: Vec<Sphere> = (0..40)
            .map(|_| Sphere::new([next() * 6.0 - 3.0, next() * 6.0 - 3.0, 0.3 + next() * 2.0], 0.05 + 0.25 * next()))
            .collect();
        let tree = BlockerTree::new(&spheres, 0.0);
        let (mut unreached, mut seen_from_reached) = (0, 0);
        for degrees in [0.5f64, 2.0, 10.0] {
            let half = degrees.to_radians();
            let cone = [half.sin(), half.cos()];
            for (elevation, azimuth) in [(20f64, 10f64), (35.0, 150.0), (50.0, -100.0), (80.0, 45.0)] {
                let (e, a) = (elevation.to_radians(), azimuth.to_radians());
                let axis = [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()];
                for _ in 0..60 {
                    let q = [next() * 8.0 - 4.0, next() * 8.0 - 4.0, next() * 0.2];
                    let spread = [0.01, 0.1, 1.0][(next() * 3.0) as usize % 3];
                    let reaches = tree.cone_may_reach(q, spread, axis, cone);
                    let mut any_seen = false;
                    for k in 0..48 {
                        let z = 2.0 * next() - 1.0;
                        let phi = 2.0 * std::f64::consts::PI * next();
                        let r = (1.0 - z * z).sqrt();
                        let length = if k % 3 == 0 { spread } else { spread * next() };
                        let p = [0, 1, 2].map(|i| q[i] + length * [r * phi.cos(), r * phi.sin(), z][i]);
                        let tilt = 0.6 * next();
                        let n = [tilt * phi.sin(), tilt * phi.cos(), (1.0 - tilt * tilt).sqrt()];
                        let mut seen = 0;
                        tree.visit_cone(p, n, 0, axis, cone, |_| {
                            seen += 1;
                            ControlFlow::Continue(())
                        });
                        assert!(reaches || seen == 0, "{degrees} deg cone at {axis:?}: {seen} seen from {p:?}");
                        any_seen |= seen > 0;
                    }
                    unreached += usize::from(!reaches);
                    seen_from_reached += usize::from(any_seen);
                }
            }
        }
        assert!(unreached > 200 && seen_from_reached > 100, "{unreached} unreached, {seen_from_reached} seen");
    }

    #[test]
    fn without_clusters_every_sphere_in_front_is_seen() {
        let spheres = cloud(500);
        let tree = BlockerTree::new(&spheres, 0.0);
        let (p, n) = ([0.3, -0.2, 0.0], [0.0, 0.6, 0.8]);
        let mut seen = Vec::new();
        tree.visit(p, n, 0, |s, _| seen.push(*s));
        let mut expected: Vec<Sphere> = spheres
            .iter()
            .copied()
            .filter(|s| (0..3).map(|k| (s.center[k] - p[k]) * n[k]).sum::<f64>() >= -s.radius)
            .collect();
        let key = |s: &Sphere| (s.center[0].to_bits(), s.center[1].to_bits(), s.center[2].to_bits());
        seen.sort_by_key(key);
        expected.sort_by_key(key);
        assert_eq!(seen, expected);
    }

    #[test]
    fn distant_clusters_are_few_caps_of_the_same_solid_angle() {
        let spheres = cloud(10_000);
        let tree = BlockerTree::new(&spheres, 0.15);
        let p = [0.0, 0.0, -40.0];
        let mut seen = Vec::new();
        tree.visit(p, [0.0, 0.0, 1.0], 0, |s, _| seen.push(*s));
        assert!(seen.len() < 100, "{} caps seen", seen.len());
        let solid_angle = |list: &[Sphere]| -> f64 {
            list.iter()
                .map(|s| {
                    let d = (0..3).map(|k| (s.center[k] - p[k]).powi(2)).sum::<f64>();
                    std::f64::consts::PI * s.radius * s.radius / d
                })
                .sum()
        };
        let (merged, all) = (solid_angle(&seen), solid_angle(&spheres));
        assert!((merged / all - 1.0).abs() < 0.05, "merged {merged} against {all}");
    }

    #[test]
    fn own_spheres_holding_the_receiver_are_not_seen() {
        let mut spheres = vec![Sphere { center: [0.0, 0.0, 1.0], radius: 1.0, object: 3 }];
        spheres.push(Sphere { center: [0.0, 0.0, 1.0], radius: 1.0, object: 4 });
        let tree = BlockerTree::new(&spheres, 0.15);
        let mut seen = Vec::new();
        tree.visit([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 3, |s, _| seen.push(s.object));
        assert_eq!(seen, vec![4]);
    }
}
