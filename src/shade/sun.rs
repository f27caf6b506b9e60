//! Sharp lights shaded outside SH: a sun is a disk too narrow for order-n SH (its
//! projection rings, and exponentiated visibility blurs its shadow over tens of degrees),
//! so it is treated apart from the environment, as SN08 (paper 004, Sections 4 and 6)
//! treats key lights, with its own visibility per pixel.
//!
//! # The disk integral
//!
//! A sun of half-angle `a` and strength `S` reflects `disk_integral * mean(V * BRDF)`
//! ([`SunLight::disk_integral`]), the mean taken over [`DISK_DIRECTIONS`] directions spread
//! uniformly by solid angle over the disk (a golden-angle spiral; see [`disk_pattern`]).
//! Each direction stands for a patch of the disk of angular radius `rho = a /
//! sqrt(DISK_DIRECTIONS)`, and its visibility is that patch's uncovered fraction,
//! approximated from the signed angle `x` to the nearest occluder boundary, `clamp(1/2 +
//! sin(x) / (2 rho))` per occluder (the sine is the angle where the clamp is not reached,
//! and needs no inverse trigonometry), the largest one taken (so overlapping occluders
//! are not counted twice). Penumbrae are therefore continuous and as wide as
//! the disk, whatever the SH order. The occluders:
//!
//! - the tangent plane: the boundary is elevation 0 above it;
//! - every sphere that reaches the disk's cone, exactly (not the clusters of the
//!   environment's hierarchy: [`BlockerTree::visit_cone`]): a cap of half-angle
//!   `asin(r / d)` about the sphere's direction; a receiver inside a sphere sees it as the
//!   half-space towards its centre (as the reference's surface band does); the receiver's
//!   own spheres behind its tangent plane cast nothing (the self-shadowing rule); or, for
//!   a sun whose frame holds its shadow map, the blocker meshes themselves, from the map
//!   ([`super::sun_shadow`]);
//! - the ground plane, for a receiver above it: the horizontal (not for a lamp above the
//!   plane too, whose light never crosses it);
//! - the height field: its horizon marched once along the sun's azimuth
//!   ([`HorizonPyramid::horizon_along`], SN08's single-azimuth swath), against each
//!   direction's elevation.
//!
//! A point lamp ([`PointLight`]) is a disk too, seen from each receiver
//! ([`SunDisk::of_lamp`]): built per pixel, its occluders restricted to those nearer than
//! the lamp (paper 002: the horizon only up to the light's distance). Its horizon is the
//! highest surface before it, below the horizontal too (thesis Section 4.3.1, Eq. 4.23;
//! [`crate::heightfield::lowest_horizon`]): a lamp low in a valley lights the slopes
//! above it that face it.
//!
//! The BRDF is evaluated per direction (the cosine lobe, the Phong lobe), so a sun that
//! grazes the surface or a highlight narrower than the disk is integrated, not sampled at
//! the centre. Where no occluder covers the disk and it lies wholly above the tangent
//! plane ([`DiskSeen::Open`]), the cosine lobe is linear over it, and its mean is its
//! value at the directions' mean ([`SunDisk::diffuse_reflected`]).

use super::blocker_tree::BlockerTree;
use super::sun_shadow::{drift_per_depth, ShadowMapMarch};
use crate::heightfield::{lowest_horizon, ElevationBand, HorizonAgainst, HorizonPyramid};
use crate::logsh::Lobe;
use crate::scene::{PointLight, SunLight};
use crate::vector::{dot, frame_around};
use std::f64::consts::{FRAC_PI_2, PI};
use std::ops::ControlFlow;

/// Directions per sun disk (per pixel, each tested against the disk's occluders).
pub const DISK_DIRECTIONS: usize = 32;

/// Points spread uniformly over the unit disk: point `i` at radius `sqrt((i + 1/2)/K)`
/// and angle `i` times the golden angle. Mapped to a cap by solid angle, they are
/// uniform on it.
pub fn disk_pattern() -> [[f64; 2]; DISK_DIRECTIONS] {
    DISK_PATTERN.0
}

/// A point of [`disk_pattern`] in polar form: its squared radius and unit direction.
type PolarPoint = (f64, [f64; 2]);

/// [`disk_pattern`], and each point in polar form, computed once (a disk is built per
/// pixel).
static DISK_PATTERN: std::sync::LazyLock<([[f64; 2]; DISK_DIRECTIONS], [PolarPoint; DISK_DIRECTIONS])> =
    std::sync::LazyLock::new(|| {
        let golden = PI * (3.0 - 5f64.sqrt());
        let points: [[f64; 2]; DISK_DIRECTIONS] = std::array::from_fn(|i| {
            let r = ((i as f64 + 0.5) / DISK_DIRECTIONS as f64).sqrt();
            let (s, c) = (golden * i as f64).sin_cos();
            [r * c, r * s]
        });
        let polar = points.map(|[x, y]| {
            let r2 = x * x + y * y;
            (r2, if r2 > 0.0 { [x / r2.sqrt(), y / r2.sqrt()] } else { [1.0, 0.0] })
        });
        (points, polar)
    });

/// Angular radius of the patch of a disk of half-angle `half_angle` that each of its
/// [`DISK_DIRECTIONS`] directions stands for.
pub fn patch_radius(half_angle: f64) -> f64 {
    half_angle / (DISK_DIRECTIONS as f64).sqrt()
}

/// A cone of directions about an axis, spread uniformly by solid angle ([`disk_pattern`]),
/// with the visibility test of the module doc: a sun's disk, or the core of a sharp
/// glossy lobe ([`super::glossy`]).
#[derive(Clone, Debug)]
pub struct DiskDirections {
    pub axis: [f64; 3],
    pub half_angle: f64,
    /// Unit directions over the disk, uniform by solid angle.
    pub directions: [[f64; 3]; DISK_DIRECTIONS],
    /// The directions by coordinate, `by_axis[k][i] = directions[i][k]`, as the blockers'
    /// caps are tested against them ([`cover_by_cap`]).
    by_axis: [[f64; DISK_DIRECTIONS]; 3],
    /// Angular radius of the patch each direction stands for.
    pub patch: f64,
    /// The mean of `directions` (not of unit length): a function linear in `w . v` over
    /// the disk has its mean there ([`SunDisk::diffuse_reflected`]).
    mean_direction: [f64; 3],
    /// The sine and cosine of `half_angle + patch`, the cone the blockers are culled
    /// against ([`BlockerTree::visit_cone`]).
    cone: [f64; 2],
    /// The least `w . axis` and the largest `|w - (w . axis) axis|` over the directions:
    /// what bounds their height above a tangent plane ([`Self::clear_of_tangent`]).
    least_along: f64,
    most_across: f64,
    /// Unit xy of the axis's azimuth (for the horizon), `None` for an axis at the zenith
    /// or nadir, where every azimuth's horizon is the same to the disk.
    pub azimuth: Option<[f64; 2]>,
    /// Distance to the light along the axis: a blocker wholly beyond it, or terrain
    /// beyond it, casts nothing (paper 002's horizon restricted to a local light's
    /// distance). Infinite for a sun or a lobe.
    pub reach: f64,
    /// [`Self::horizon_band`], computed at its first use (a sun's disk is built once and
    /// read per pixel).
    band: std::sync::OnceLock<ElevationBand>,
}

/// Which planes a disk's visibility test counts besides the blockers and the height
/// field.
#[derive(Clone, Copy, Debug)]
pub struct Planes {
    /// The receiver's tangent plane.
    pub tangent: bool,
    /// The scene's ground plane, at this height, for a receiver above it.
    pub ground: Option<f64>,
}

/// A disk's directions about +Z, which depend on its half-angle alone: computed once per
/// sun or glossy lobe and turned to each receiver's axis ([`DiskDirections::of_shape`]).
#[derive(Clone, Debug)]
pub struct DiskShape {
    pub half_angle: f64,
    /// `(sin theta cos phi, sin theta sin phi, cos theta)` of each direction.
    local: [[f64; 3]; DISK_DIRECTIONS],
    /// The mean of `local` ([`DiskDirections::mean_direction`]).
    local_mean: [f64; 3],
    /// [`DiskDirections::cone`]: a sun's is computed once, not per pixel.
    cone: [f64; 2],
}

impl DiskShape {
    /// The disk of half-angle `half_angle` (in `(0, pi/2]`) about +Z.
    pub fn new(half_angle: f64) -> Self {
        let one_minus_cos = 1.0 - half_angle.cos();
        let local = DISK_PATTERN.1.map(|(r2, [cos_phi, sin_phi])| {
            let cos_theta = 1.0 - one_minus_cos * r2;
            let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
            [sin_theta * cos_phi, sin_theta * sin_phi, cos_theta]
        });
        let (sin_cone, cos_cone) = (half_angle + patch_radius(half_angle)).sin_cos();
        let local_mean = [0, 1, 2].map(|k| local.iter().map(|w| w[k]).sum::<f64>() / DISK_DIRECTIONS as f64);
        Self { half_angle, local, local_mean, cone: [sin_cone, cos_cone] }
    }
}

impl DiskDirections {
    /// The disk of half-angle `half_angle` (in `(0, pi/2]`) about unit `axis`.
    pub fn new(axis: [f64; 3], half_angle: f64) -> Self {
        Self::of_shape(axis, &DiskShape::new(half_angle))
    }

    /// The disk of `shape` about unit `axis`.
    pub fn of_shape(axis: [f64; 3], shape: &DiskShape) -> Self {
        let (e1, e2) = frame_around(axis);
        let half_angle = shape.half_angle;
        let directions = shape.local.map(|[x, y, z]| [0, 1, 2].map(|k| z * axis[k] + x * e1[k] + y * e2[k]));
        let horizontal = axis[0].hypot(axis[1]);
        Self {
            axis,
            half_angle,
            directions,
            by_axis: std::array::from_fn(|k| directions.map(|w| w[k])),
            patch: patch_radius(half_angle),
            mean_direction: {
                let [x, y, z] = shape.local_mean;
                [0, 1, 2].map(|k| z * axis[k] + x * e1[k] + y * e2[k])
            },
            cone: shape.cone,
            least_along: directions.iter().map(|&w| dot(w, axis)).fold(f64::INFINITY, f64::min),
            most_across: directions
                .iter()
                .map(|&w| {
                    let along = dot(w, axis);
                    let across = [0, 1, 2].map(|k| w[k] - along * axis[k]);
                    dot(across, across).sqrt()
                })
                .fold(0.0, f64::max),
            azimuth: (horizontal > 1e-9).then(|| [axis[0] / horizontal, axis[1] / horizontal]),
            reach: f64::INFINITY,
            band: std::sync::OnceLock::new(),
        }
    }

    /// The elevations between which the height field's horizon changes the disk's
    /// visibility: a horizon a patch below its lowest direction covers none of any
    /// direction's patch, one a patch above its highest covers all of every one (the
    /// share of the module doc, clamped), to the bit; 1e-9 rad of margin each way, far
    /// above the rounding of the share's terms. The march stops once it knows the horizon
    /// is outside ([`HorizonPyramid::horizon_against`]). With the march's other stop (no
    /// later step can raise the horizon), the horizons are the same bits.
    fn horizon_band(&self) -> ElevationBand {
        *self.band.get_or_init(|| self.computed_horizon_band())
    }

    /// [`Self::horizon_band`] computed.
    fn computed_horizon_band(&self) -> ElevationBand {
        const MARGIN: f64 = 1e-9;
        let (lowest, highest) = self
            .directions
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(low, high), w| (low.min(w[2]), high.max(w[2])));
        let patch = self.patch.min(1.0).asin();
        let foot = lowest.clamp(-1.0, 1.0).asin() - patch - MARGIN;
        let top = highest.clamp(-1.0, 1.0).asin() + patch + MARGIN;
        ElevationBand {
            below: if foot > lowest_horizon(self.reach).atan() { foot.tan() } else { f64::NEG_INFINITY },
            above: if top < FRAC_PI_2 - MARGIN { top.tan() } else { f64::INFINITY },
        }
    }

    /// Visibility of each direction, in `[0, 1]`, at `p` with unit normal `n` on object
    /// `object` (module doc), against the blockers, the height field and `planes`.
    pub fn visibility(
        &self,
        blockers: Option<&BlockerTree>,
        horizons: Option<&HorizonPyramid>,
        planes: Planes,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
    ) -> [f64; DISK_DIRECTIONS] {
        let horizon = horizons.map_or(DiskHorizon::None, DiskHorizon::Marched);
        self.seen_against(Casters::from(blockers), horizon, planes, p, n, object).visibility()
    }

    /// Whether `planes` alone hide the whole disk at `p` with unit normal `n` (a sun
    /// behind the surface): [`Self::visibility`] is then 0 without a march.
    pub fn hidden_by_planes(&self, planes: Planes, p: [f64; 3], n: [f64; 3]) -> bool {
        let ground = self.ground_counts(planes.ground, p);
        if self.planes_cover_nothing(planes.tangent, ground, n) {
            return false;
        }
        self.shares_of_planes(planes.tangent, ground, n).iter().all(|&share| share >= 1.0)
    }

    /// Whether the ground plane at `ground` hides the directions below the horizontal from
    /// `p`: for a receiver above it, unless the light is a lamp above it too, whose light
    /// reaches `p` without crossing the plane (a lantern over a valley floor, seen from
    /// the slopes above it).
    fn ground_counts(&self, ground: Option<f64>, p: [f64; 3]) -> bool {
        let light_above = |z: f64| self.reach.is_finite() && p[2] + self.axis[2] * self.reach > z;
        ground.is_some_and(|z| super::point::above_ground(p, z) && !light_above(z))
    }

    /// Whether every direction lies more than a patch above the tangent plane of normal
    /// `n`, which then covers none of any patch: `w . n >= (w . axis)(n . axis) - |w_perp|
    /// |n_perp|`, with 1e-9 of margin, far above the rounding of a dot product. Most lit
    /// pixels are so, and their planes' shares are then 0 without a test per direction.
    /// Compared squared, both sides nonnegative, without the square root of `|n_perp|`.
    fn clear_of_tangent(&self, n: [f64; 3]) -> bool {
        const MARGIN: f64 = 1e-9;
        let along = dot(n, self.axis);
        let across_squared = (dot(n, n) - along * along).max(0.0);
        let clearance = self.least_along * along - (self.patch + MARGIN);
        along >= 0.0
            && clearance >= 0.0
            && clearance * clearance >= self.most_across * self.most_across * across_squared
    }

    /// Whether the planes counted (the tangent plane of normal `n` where `tangent`, the
    /// ground where `ground`) cover none of any direction's patch, known without a test
    /// per direction: no ground, and no tangent plane or one the disk is clear of.
    fn planes_cover_nothing(&self, tangent: bool, ground: bool, n: [f64; 3]) -> bool {
        !ground && (!tangent || self.clear_of_tangent(n))
    }

    /// The share of each direction's patch that the tangent plane of normal `n` (where
    /// `tangent`) and the ground (where `ground`) cover, the larger: four directions per
    /// instruction where the processor has AVX2 ([`four_directions_at_once`]).
    fn shares_of_planes(&self, tangent: bool, ground: bool, n: [f64; 3]) -> [f64; DISK_DIRECTIONS] {
        let (by_axis, two_patches) = (&self.by_axis, 2.0 * self.patch);
        four_directions_at_once(
            #[inline(always)]
            || {
                let covered = |sin_x: f64| (0.5 + sin_x / two_patches).clamp(0.0, 1.0);
                let mut shares = [0.0f64; DISK_DIRECTIONS];
                for (i, share) in shares.iter_mut().enumerate() {
                    let along = along_direction(by_axis, i, n);
                    let by_tangent = if tangent { 0.0f64.max(covered(-along)) } else { 0.0 };
                    *share = if ground { by_tangent.max(covered(-by_axis[2][i])) } else { by_tangent };
                }
                shares
            },
        )
    }

    /// The elevations between which the height field's horizon changes the disk's
    /// visibility (`Self::horizon_band`), where its axis has an azimuth to march: what
    /// a frame's horizons are marched against before its pixels are shaded
    /// ([`DiskHorizon::Known`]).
    pub fn march_band(&self) -> Option<MarchAlong> {
        let horizontal_reach = self.reach * self.axis[0].hypot(self.axis[1]);
        self.azimuth.map(|azimuth| MarchAlong { azimuth, horizontal_reach, band: self.horizon_band() })
    }

    /// Whether a blocker of `tree` may reach the disk's cone from some receiver within
    /// `spread` of `q` ([`BlockerTree::cone_may_reach`]): where none can, the blockers
    /// change no visibility there.
    pub fn blockers_may_reach(&self, tree: &BlockerTree, q: [f64; 3], spread: f64) -> bool {
        tree.cone_may_reach(q, spread, self.axis, self.cone)
    }

    /// [`Self::visibility`] with the height field's horizon from `horizon` (marched here,
    /// or marched already with the other pixels of a frame:
    /// [`HorizonPyramid::horizons_against`], the same bits) and `casters` for the blockers
    /// (their spheres, or a sun's shadow map of their meshes), told as [`DiskSeen`]: a disk
    /// that nothing covers and that lies clear of the tangent plane is [`DiskSeen::Open`]
    /// without a visibility per direction (97 % of the surface pixels and lamps of the
    /// Sun-lamp scene's three lamps turned 75 deg, whose turn then takes two thirds of
    /// the time).
    pub fn seen_against(
        &self,
        casters: Casters,
        horizon: DiskHorizon,
        planes: Planes,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
    ) -> DiskSeen {
        let two_patches = 2.0 * self.patch;
        // The blocked share from the sine of the signed angle `x` from the occluder's
        // boundary (positive inside it): within the patch, where the share is not clamped,
        // `sin x` is `x` to `x^3 / 6`, and it needs no inverse trigonometry, which GPUs
        // only guarantee to 4096 ulp (shaders/disk.wgsl computes the same).
        let covered = |sin_x: f64| (0.5 + sin_x / two_patches).clamp(0.0, 1.0);
        // Blocked share per direction, the largest over the occluders; `None` while
        // nothing covers any (the planes counted being the tangent plane, clear of it).
        let ground = self.ground_counts(planes.ground, p);
        let mut blocked = if self.planes_cover_nothing(planes.tangent, ground, n) {
            (!planes.tangent).then_some([0.0; DISK_DIRECTIONS])
        } else {
            let shares = self.shares_of_planes(planes.tangent, ground, n);
            // Hidden wholly (a sun behind the surface): no occluder can hide more.
            if shares.iter().all(|&b| b >= 1.0) {
                return DiskSeen::Hidden;
            }
            Some(shares)
        };
        let against = match horizon {
            DiskHorizon::None => None,
            DiskHorizon::Known(against) => self.azimuth.map(|_| against),
            DiskHorizon::Marched(pyramid) => self
                .march_band()
                .map(|along| pyramid.horizon_against(p, along.azimuth, along.horizontal_reach, along.band)),
        };
        if let Some(against) = against {
            match against {
                HorizonAgainst::Below => {}
                HorizonAgainst::Above => return DiskSeen::Hidden,
                HorizonAgainst::At(horizon) => {
                    let (sin_h, cos_h) = horizon.sin_cos();
                    let blocked = blocked.get_or_insert([0.0; DISK_DIRECTIONS]);
                    for (b, w) in blocked.iter_mut().zip(&self.directions) {
                        // x = horizon - elevation, in [-pi, pi] (a lamp's horizon may lie
                        // below the horizontal): past pi/2 either way it is deep inside or
                        // far outside, as the horizon is above the direction or below it.
                        let (sin_e, cos_e) = (w[2], (1.0 - w[2] * w[2]).max(0.0).sqrt());
                        let cos_x = cos_h * cos_e + sin_h * sin_e;
                        let share = match cos_x < 0.0 {
                            true => f64::from(u8::from(sin_h > sin_e)),
                            false => covered(sin_h * cos_e - cos_h * sin_e),
                        };
                        *b = b.max(share);
                    }
                }
            }
        }
        if let Casters::Map(map) = casters {
            if let Some(hidden) = map.blocked(&self.directions, drift_per_depth(self.half_angle), p, n) {
                let blocked = blocked.get_or_insert([0.0; DISK_DIRECTIONS]);
                for (b, hidden) in blocked.iter_mut().zip(hidden) {
                    if hidden {
                        *b = 1.0;
                    }
                }
            }
        } else if let Casters::Spheres(tree) = casters {
            tree.visit_cone(p, n, object, self.axis, self.cone, |sphere| {
                let d = [0, 1, 2].map(|k| sphere.center[k] - p[k]);
                let distance = dot(d, d).sqrt();
                if !(distance > 0.0)
                    || distance - sphere.radius >= self.reach
                    || (object != 0 && sphere.object == object && dot(d, n) <= 0.0)
                {
                    return ControlFlow::Continue(());
                }
                let axis = d.map(|c| c / distance);
                // The cap's half-angle: asin(r / d), a hemisphere from inside.
                let sin_cap = (sphere.radius / distance).min(1.0);
                let cos_cap = (1.0 - sin_cap * sin_cap).sqrt();
                let blocked = blocked.get_or_insert([0.0; DISK_DIRECTIONS]);
                cover_by_cap(&self.by_axis, axis, [sin_cap, cos_cap], two_patches, blocked);
                // Wholly covered (an umbra): no other sphere can cover more.
                if blocked.iter().all(|&b| b >= 1.0) {
                    return ControlFlow::Break(());
                }
                ControlFlow::Continue(())
            });
        }
        match blocked {
            None => DiskSeen::Open,
            Some(blocked) => DiskSeen::Partial(blocked.map(|b| 1.0 - b)),
        }
    }
}

/// What casts shadows on a disk besides the planes and the height field.
#[derive(Clone, Copy, Debug)]
pub enum Casters<'a> {
    None,
    /// The blocker spheres, each sphere that reaches the disk's cone.
    Spheres(&'a BlockerTree),
    /// A sun's shadow map of the blocker meshes ([`super::sun_shadow`]), in place of the
    /// spheres.
    Map(&'a ShadowMapMarch),
}

impl<'a> From<Option<&'a BlockerTree>> for Casters<'a> {
    fn from(blockers: Option<&'a BlockerTree>) -> Self {
        blockers.map_or(Casters::None, Casters::Spheres)
    }
}

/// What a disk's occluders leave of it at a receiver ([`DiskDirections::seen_against`]).
/// One lives per pixel and lamp, on the stack: boxing the visibility would allocate for
/// each partly covered disk.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub enum DiskSeen {
    /// Every direction wholly visible, and more than a patch above the tangent plane.
    Open,
    /// Each direction's visibility, in `[0, 1]` (all of them 0 where the blockers and the
    /// horizon hide the whole disk).
    Partial([f64; DISK_DIRECTIONS]),
    /// Wholly hidden by the planes or the height field's horizon.
    Hidden,
}

impl DiskSeen {
    /// Each direction's visibility, in `[0, 1]`.
    pub fn visibility(self) -> [f64; DISK_DIRECTIONS] {
        match self {
            DiskSeen::Open => [1.0; DISK_DIRECTIONS],
            DiskSeen::Partial(visibility) => visibility,
            DiskSeen::Hidden => [0.0; DISK_DIRECTIONS],
        }
    }

    /// Whether no direction is visible at all.
    pub fn is_dark(&self) -> bool {
        match self {
            DiskSeen::Open => false,
            DiskSeen::Partial(visibility) => visibility.iter().all(|&v| v == 0.0),
            DiskSeen::Hidden => true,
        }
    }
}

/// `work` over a disk's directions, compiled for AVX2 where the processor has it: the same
/// operations in the same order, so the same bits, four directions per instruction.
#[inline(always)]
fn four_directions_at_once<R>(work: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if *crate::x86::AVX2 {
        #[target_feature(enable = "avx2")]
        unsafe fn avx2<R>(work: impl FnOnce() -> R) -> R {
            work()
        }
        // SAFETY: the processor has AVX2.
        return unsafe { avx2(work) };
    }
    work()
}

/// Raises each direction's blocked share to what a cap about unit `axis` of half-angle
/// with sine and cosine `cap` covers of its patch (module doc): the signed angle `x = cap -
/// angle` from the cap's boundary, by its sine, without inverse trigonometry; below `-pi/2`
/// it is far outside. The directions are given by coordinate, `by_axis[k][i]`, four per
/// instruction where the processor has AVX2 ([`four_directions_at_once`]).
fn cover_by_cap(
    by_axis: &[[f64; DISK_DIRECTIONS]; 3],
    axis: [f64; 3],
    [sin_cap, cos_cap]: [f64; 2],
    two_patches: f64,
    blocked: &mut [f64; DISK_DIRECTIONS],
) {
    four_directions_at_once(
        #[inline(always)]
        || {
            for i in 0..DISK_DIRECTIONS {
                let cos_a = along_direction(by_axis, i, axis);
                let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
                let cos_x = cos_cap * cos_a + sin_cap * sin_a;
                let share = (0.5 + (sin_cap * cos_a - cos_cap * sin_a) / two_patches).clamp(0.0, 1.0);
                blocked[i] = blocked[i].max(if cos_x < 0.0 { 0.0 } else { share });
            }
        },
    )
}

/// The dot product of `v` with direction `i` of a disk given by coordinate
/// (`by_axis[k][i]`), in the order each of its readers summed it before (the same bits).
#[inline(always)]
fn along_direction(by_axis: &[[f64; DISK_DIRECTIONS]; 3], i: usize, v: [f64; 3]) -> f64 {
    v[0] * by_axis[0][i] + v[1] * by_axis[1][i] + v[2] * by_axis[2][i]
}

/// How a disk's horizon is marched ([`HorizonPyramid::horizon_against`]'s arguments but
/// the receiver).
#[derive(Clone, Copy, Debug)]
pub struct MarchAlong {
    /// Unit xy of the axis's azimuth.
    pub azimuth: [f64; 2],
    /// How far the march may go, horizontally ([`DiskDirections::reach`]).
    pub horizontal_reach: f64,
    pub band: ElevationBand,
}

/// Where a disk's visibility takes the height field's horizon from.
#[derive(Clone, Copy, Debug)]
pub enum DiskHorizon<'a> {
    /// No height field.
    None,
    /// Marched along the disk's azimuth from the receiver, against its band.
    Marched(&'a HorizonPyramid),
    /// Marched so already ([`DiskDirections::march_band`]).
    Known(HorizonAgainst),
}

/// A sun prepared for shading: its disk's directions and what they integrate to.
#[derive(Clone, Debug)]
pub struct SunDisk {
    pub light: SunLight,
    pub disk: DiskDirections,
    /// [`SunLight::disk_integral`].
    pub disk_integral: [f64; 3],
}

impl SunDisk {
    pub fn new(light: &SunLight) -> Self {
        Self {
            light: *light,
            disk: DiskDirections::new(light.direction, light.half_angle),
            disk_integral: light.disk_integral(),
        }
    }

    /// A point lamp's disk at one receiver ([`PointLight::seen_from`]): nothing beyond the
    /// lamp's centre shadows it.
    pub fn of_lamp(lamp: &PointLight, p: [f64; 3], n: [f64; 3]) -> Self {
        let (light, reach) = lamp.seen_from(p, n);
        let mut disk = Self::new(&light);
        disk.disk.reach = reach;
        disk
    }

    /// What the occluders leave of the disk at `p` with unit normal `n` on object `object`
    /// (module doc): the tangent plane, the ground plane at `ground`, the height field
    /// (its horizon from `horizon`) and `casters` ([`DiskDirections::seen_against`]).
    pub fn seen(
        &self,
        casters: Casters,
        horizon: DiskHorizon,
        ground: Option<f64>,
        p: [f64; 3],
        n: [f64; 3],
        object: u32,
    ) -> DiskSeen {
        self.disk.seen_against(casters, horizon, Planes { tangent: true, ground }, p, n, object)
    }

    /// `integral over the disk of L V lobe(axis . w) dw` for a lobe given by its value at `cos theta` from `axis`, given the disk's
    /// visibility: `disk_integral * mean(V lobe)`, RGB.
    pub fn reflected(
        &self,
        visibility: &[f64; DISK_DIRECTIONS],
        lobe: impl Fn(f64) -> f64,
        axis: [f64; 3],
    ) -> [f64; 3] {
        self.disk_mean(axis, |i, z| visibility[i] * lobe(z))
    }

    /// [`Self::reflected`] of the disk as `seen`: for [`DiskSeen::Open`], the same bits as
    /// a visibility of 1 throughout, without it.
    pub fn reflected_seen(&self, seen: &DiskSeen, lobe: impl Fn(f64) -> f64, axis: [f64; 3]) -> [f64; 3] {
        match seen {
            DiskSeen::Open => self.disk_mean(axis, |_, z| lobe(z)),
            DiskSeen::Partial(visibility) => self.reflected(visibility, lobe, axis),
            DiskSeen::Hidden => [0.0; 3],
        }
    }

    /// `integral over the disk of L V brdf(n . w, v . w) dw` for the disk as `seen`: a
    /// lobe that depends on the direction through two axes, such as GGX's BRDF times the
    /// cosine ([`super::glossy::ggx_lit`]). Where the lobe is `smooth` over the disk
    /// ([`super::glossy::smooth_over_disk`]), an open disk takes its value at the axis.
    pub fn reflected_between_seen(
        &self,
        seen: &DiskSeen,
        brdf: impl Fn(f64, f64) -> f64,
        smooth: bool,
        n: [f64; 3],
        v: [f64; 3],
    ) -> [f64; 3] {
        let by_axis = &self.disk.by_axis;
        let term = |i: usize, n_w: f64| brdf(n_w, along_direction(by_axis, i, v));
        match seen {
            DiskSeen::Open if smooth => {
                let at_axis = brdf(dot(self.disk.axis, n), dot(self.disk.axis, v));
                self.disk_integral.map(|c| c * at_axis)
            }
            DiskSeen::Open => self.disk_mean(n, term),
            DiskSeen::Partial(visibility) => self.disk_mean(n, |i, n_w| visibility[i] * term(i, n_w)),
            DiskSeen::Hidden => [0.0; 3],
        }
    }

    /// [`Self::reflected_seen`] of the cosine lobe about the receiver's normal `n`. An
    /// open disk lies wholly above the tangent plane, where the lobe is linear in `n . w`:
    /// its mean over the directions is its value at their mean, one dot product where
    /// [`Self::reflected`] takes 32, equal to rounding (within 1e-14 relative, tested).
    pub fn diffuse_reflected(&self, seen: &DiskSeen, n: [f64; 3]) -> [f64; 3] {
        match seen {
            DiskSeen::Open => {
                let mean = Lobe::Diffuse.value(dot(self.disk.mean_direction, n));
                self.disk_integral.map(|c| c * mean)
            }
            _ => self.reflected_seen(seen, |z| Lobe::Diffuse.value(z), n),
        }
    }

    /// `disk_integral * mean(term(i, axis . w_i))` over the disk's directions `w_i`.
    #[inline(always)]
    fn disk_mean(&self, axis: [f64; 3], term: impl Fn(usize, f64) -> f64) -> [f64; 3] {
        // Four running sums, directions `4i + k` in sum `k`: four chains of additions the
        // processor overlaps, where one chain of 32 was two fifths of a turned Sun lamp's
        // lobes, and four directions per instruction where it has AVX2. The same sum to
        // rounding.
        let by_axis = &self.disk.by_axis;
        let sums = four_directions_at_once(
            #[inline(always)]
            || {
                let mut sums = [0.0f64; 4];
                for four in (0..DISK_DIRECTIONS).step_by(4) {
                    for (k, sum) in sums.iter_mut().enumerate() {
                        let i = four + k;
                        let z = along_direction(by_axis, i, axis);
                        *sum += term(i, z);
                    }
                }
                sums
            },
        );
        let mean = ((sums[0] + sums[1]) + (sums[2] + sums[3])) / DISK_DIRECTIONS as f64;
        self.disk_integral.map(|c| c * mean)
    }
}

/// Solid angle of the intersection of two spherical caps of half-angles `a` and `b`
/// whose axes are `gamma` apart (Tovchigrechko and Vakser 2001, Eq. 4; the lune formula
/// of Mazonka 2012): the closed form the sun's disk test is checked against.
pub fn cap_overlap(a: f64, b: f64, gamma: f64) -> f64 {
    let cap = |x: f64| 2.0 * PI * (1.0 - x.cos());
    if gamma >= a + b {
        return 0.0;
    }
    if gamma <= (a - b).abs() {
        return cap(a.min(b));
    }
    let (ca, cb, cg) = (a.cos(), b.cos(), gamma.cos());
    let (sa, sb, sg) = (a.sin(), b.sin(), gamma.sin());
    let clamp = |x: f64| x.clamp(-1.0, 1.0);
    2.0 * (PI
        - clamp((cg - ca * cb) / (sa * sb)).acos()
        - ca * clamp((cb - cg * ca) / (sg * sa)).acos()
        - cb * clamp((ca - cg * cb) / (sg * sb)).acos())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Sphere;
    use crate::shade::glossy::SharpLobe;

    /// The share of direction `w`'s patch that the tangent plane of `n` (where `tangent`)
    /// and the ground (where `ground`) cover, the larger, for one direction as the module
    /// doc gives it: what [`DiskDirections::shares_of_planes`] computes four at a time.
    fn share_of_direction(disk: &DiskDirections, tangent: bool, ground: bool, n: [f64; 3], w: [f64; 3]) -> f64 {
        let covered = |sin_x: f64| (0.5 + sin_x / (2.0 * disk.patch)).clamp(0.0, 1.0);
        let by_tangent = if tangent { 0.0f64.max(covered(-dot(n, w))) } else { 0.0 };
        if ground {
            by_tangent.max(covered(-w[2]))
        } else {
            by_tangent
        }
    }

    /// The planes' shares and a disk's lobes, computed four directions at a time, are the
    /// sums of the directions one at a time, bit for bit (the same operations in the same
    /// order): disks of three widths at five axes, normals and lobe axes on a spiral over
    /// the sphere, visibilities spread over [0, 1], the cosine lobe and a narrow GGX one.
    #[test]
    fn four_directions_at_once_are_one_at_a_time() {
        let light = |direction: [f64; 3], half_angle: f64| SunLight {
            direction,
            half_angle,
            strength: 3.0,
            color: [1.0, 0.5, 0.25],
        };
        let glossy = SharpLobe::Ggx { alpha: 0.05 };
        let lobes: [&dyn Fn(f64) -> f64; 2] = [&|z| Lobe::Diffuse.value(z), &|z| 0.7 * glossy.value(z)];
        let mut lit = 0;
        for degrees in [0.3, 2.0, 20.0] {
            for axis in [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.28, 0.96], [0.48, 0.64, 0.6], [1.0, 0.0, 0.0]] {
                let sun = SunDisk::new(&light(axis, f64::to_radians(degrees)));
                let disk = &sun.disk;
                for k in 0..500 {
                    let n = spiral_normal(k, 500, 1.0);
                    for (tangent, ground) in [(true, false), (false, true), (true, true)] {
                        let one_at_a_time = disk.directions.map(|w| share_of_direction(disk, tangent, ground, n, w));
                        let at_once = disk.shares_of_planes(tangent, ground, n);
                        assert_eq!(
                            at_once.map(f64::to_bits),
                            one_at_a_time.map(f64::to_bits),
                            "{degrees} deg, n {n:?}"
                        );
                    }
                    let visibility: [f64; DISK_DIRECTIONS] = std::array::from_fn(|i| ((i * 7 + k) % 11) as f64 / 10.0);
                    for lobe in lobes {
                        let mut sums = [0.0f64; 4];
                        for (i, w) in disk.directions.iter().enumerate() {
                            sums[i % 4] += visibility[i] * lobe(dot(n, *w));
                        }
                        let mean = ((sums[0] + sums[1]) + (sums[2] + sums[3])) / DISK_DIRECTIONS as f64;
                        let one_at_a_time = sun.disk_integral.map(|c| c * mean);
                        let at_once = sun.reflected(&visibility, lobe, n);
                        assert_eq!(
                            at_once.map(f64::to_bits),
                            one_at_a_time.map(f64::to_bits),
                            "{degrees} deg, n {n:?}"
                        );
                        lit += usize::from(mean > 0.0);
                    }
                }
            }
        }
        assert!(lit > 5000, "{lit} lobes lit");
    }

    /// Disk axes from the zenith to the horizon, two of them off the axes' planes.
    fn seven_axes() -> impl Iterator<Item = [f64; 3]> {
        [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.28, 0.96], [0.48, 0.64, 0.6], [1.0, 0.0, 0.0]]
            .into_iter()
            .chain([[0.3f64, -0.4, 0.2], [-0.5, 0.1, 0.02]].map(|v| v.map(|c| c / dot(v, v).sqrt())))
    }

    /// Normal `k` of `count` on a spiral over the sphere, its distance from the z axis
    /// times `stretch` (1 for unit length).
    fn spiral_normal(k: usize, count: usize, stretch: f64) -> [f64; 3] {
        let z = 1.0 - 2.0 * (k as f64 + 0.5) / count as f64;
        let phi = k as f64 * 2.399_963;
        let r = (1.0 - z * z).sqrt() * stretch;
        [r * phi.cos(), r * phi.sin(), z]
    }

    /// Where [`DiskDirections::clear_of_tangent`] holds, the tangent plane covers none of
    /// any direction's patch, so the planes' shares are the 0 of a test per direction, to
    /// the bit: disks 0.3 to 20 deg wide at 7 axes, normals on a sphere of directions and
    /// 1e-6 off unit length; it holds for most normals, and fails only within a quarter of
    /// the disk's half-angle of where the nearest patch touches the plane.
    #[test]
    fn a_disk_clear_of_the_tangent_plane_is_not_tested_per_direction() {
        let (mut clear, mut tested) = (0, 0);
        for degrees in [0.3, 2.0, 20.0] {
            let half_angle = f64::to_radians(degrees);
            for axis in seven_axes() {
                let disk = DiskDirections::new(axis, half_angle);
                for k in 0..2000 {
                    // A spiral over the sphere, then the length off 1 by up to 1e-6.
                    let n = spiral_normal(k, 2000, 1.0 + 1e-6 * ((k % 3) as f64 - 1.0));
                    let shares = disk.directions.map(|w| share_of_direction(&disk, true, false, n, w));
                    if disk.clear_of_tangent(n) {
                        clear += 1;
                        assert!(shares.iter().all(|s| s.to_bits() == 0), "{degrees} deg, axis {axis:?}, n {n:?}");
                        let planes = Planes { tangent: true, ground: None };
                        let seen = disk.seen_against(Casters::None, DiskHorizon::None, planes, [0.0; 3], n, 0);
                        assert!(matches!(seen, DiskSeen::Open), "{degrees} deg, axis {axis:?}, n {n:?}");
                    } else {
                        tested += 1;
                        // Not clear: some direction lies within a patch and a quarter of the
                        // disk's half-angle of the plane.
                        let lowest = disk.directions.iter().map(|&w| dot(w, n)).fold(f64::INFINITY, f64::min);
                        assert!(lowest < disk.patch + 0.25 * half_angle, "{degrees} deg, n {n:?}: {lowest}");
                    }
                }
            }
        }
        assert!(clear > tested / 2 && tested > 1000, "{clear} clear, {tested} tested");
    }

    /// An open disk's cosine lobe is its value at the directions' mean
    /// ([`SunDisk::diffuse_reflected`]): every direction of an open disk lies above the
    /// tangent plane, and the closed form is the per-direction mean to 1e-14 relative, on
    /// disks 0.3 to 20 deg wide at 7 axes and normals over the sphere; elsewhere the two
    /// are the same bits. The directions' mean is shorter than the axis by the disk's
    /// width (1 % at 20 deg): the axis in its place fails here.
    #[test]
    fn an_open_disk_reflects_the_cosine_lobe_at_its_mean_direction() {
        let (mut open, mut partial) = (0, 0);
        for degrees in [0.3, 2.0, 20.0] {
            let half_angle = f64::to_radians(degrees);
            for axis in seven_axes() {
                let sun =
                    SunDisk::new(&SunLight { direction: axis, half_angle, strength: 2.0, color: [1.0, 0.5, 0.25] });
                for k in 0..500 {
                    let z = 1.0 - 2.0 * (k as f64 + 0.5) / 500.0;
                    let phi = k as f64 * 2.399_963;
                    let r = (1.0 - z * z).sqrt();
                    let n = [r * phi.cos(), r * phi.sin(), z];
                    let per_direction = |v: &[f64; DISK_DIRECTIONS]| sun.reflected(v, |z| Lobe::Diffuse.value(z), n);
                    match sun.seen(Casters::None, DiskHorizon::None, None, [0.0; 3], n, 0) {
                        DiskSeen::Open => {
                            open += 1;
                            assert!(sun.disk.directions.iter().all(|&w| dot(w, n) > 0.0), "{degrees} deg, n {n:?}");
                            let closed = sun.diffuse_reflected(&DiskSeen::Open, n);
                            let summed = per_direction(&[1.0; DISK_DIRECTIONS]);
                            for (c, s) in closed.iter().zip(summed) {
                                assert!((c - s).abs() <= 1e-14 * s.abs(), "{degrees} deg, n {n:?}: {c} against {s}");
                            }
                        }
                        seen @ DiskSeen::Partial(v) => {
                            partial += 1;
                            let told = sun.diffuse_reflected(&seen, n);
                            assert_eq!(told.map(f64::to_bits), per_direction(&v).map(f64::to_bits));
                        }
                        DiskSeen::Hidden => {}
                    }
                }
            }
        }
        assert!(open > 3000 && partial > 100, "{open} open, {partial} partial");
    }

    /// A GGX lobe smooth over an open disk ([`smooth_over_disk`]) reflects it as its
    /// value at the axis does, within 0.2 % of the 32 directions' mean (measured: 8.9e-4):
    /// suns 0.25 to 10 degrees wide, lobes twice the least width, views and normals all
    /// around.
    #[test]
    fn a_smooth_lobe_reflects_an_open_disk_at_its_axis() {
        use crate::shade::glossy::{smooth_over_disk, GgxLit, SMOOTH_OVER_DISK};
        let (mut worst, mut compared) = (0.0f64, 0);
        for degrees in [0.25, 2.0, 10.0] {
            let half_angle = f64::to_radians(degrees);
            let alpha = 2.0 * (SMOOTH_OVER_DISK * (1.0 - half_angle.cos())).sqrt();
            for axis in seven_axes() {
                let sun =
                    SunDisk::new(&SunLight { direction: axis, half_angle, strength: 2.0, color: [1.0, 0.5, 0.25] });
                for k in 0..300 {
                    let n = spiral_normal(k, 300, 1.0);
                    if !matches!(sun.seen(Casters::None, DiskHorizon::None, None, [0.0; 3], n, 0), DiskSeen::Open) {
                        continue;
                    }
                    for j in 0..12 {
                        let v = spiral_normal(j * 25 + k % 25, 300, 1.0);
                        if dot(v, n) <= 0.05
                            || !smooth_over_disk(alpha, dot(v, n), 1.0 - half_angle.cos(), dot(n, axis))
                        {
                            continue;
                        }
                        let brdf = GgxLit::new(alpha, 0.04, dot(v, n));
                        let at_axis = sun.reflected_between_seen(&DiskSeen::Open, |a, b| brdf.value(a, b), true, n, v);
                        let mean = sun.reflected_between_seen(&DiskSeen::Open, |a, b| brdf.value(a, b), false, n, v);
                        let peak =
                            sun.disk_integral[0] * brdf.value(dot(n, v).max(0.0), 1.0).max(brdf.value(1.0, dot(n, v)));
                        if mean[0] > 1e-3 * peak {
                            worst = worst.max((at_axis[0] - mean[0]).abs() / mean[0]);
                            compared += 1;
                        }
                    }
                }
            }
        }
        println!("smooth lobes at the axis: {compared} compared, worst {worst:.1e}");
        assert!(compared > 1000, "{compared}");
        assert!(worst <= 2e-3, "worst {worst}");
    }

    /// A disk's visibility over a height field, the march told the disk's band of
    /// elevations ([`DiskDirections::horizon_band`]), equals it from the whole horizon to
    /// the bit: disks from 2 to 85 deg high, 0.3 to 20 deg wide, on and above a bumpy
    /// field, tilted normals included.
    #[test]
    fn the_horizon_band_changes_no_visibility() {
        use crate::heightfield::{HeightField, HorizonSettings};
        let (columns, rows) = (41, 41);
        let heights: Vec<f32> = (0..columns * rows)
            .map(|i| {
                let (x, y) = ((i % columns) as f32, (i / columns) as f32);
                0.9 * (0.5 * x).sin() * (0.4 * y).cos() + 0.3 * (0.17 * x - 0.23 * y).sin()
            })
            .collect();
        let field = HeightField::new(heights, columns, rows, [-5.0, -5.0], [5.0, 5.0]).unwrap();
        let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).unwrap();
        let (mut partly, mut hidden, mut open) = (0, 0, 0);
        for elevation in [2.0f64, 8.0, 20.0, 45.0, 85.0] {
            for half_angle in [0.3f64, 3.0, 20.0] {
                for azimuth in [10.0f64, 130.0, 250.0] {
                    let (e, a) = (elevation.to_radians(), azimuth.to_radians());
                    let axis = [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()];
                    let disk = DiskDirections::new(axis, half_angle.to_radians());
                    for i in 0..25 {
                        let (x, y) = (-4.0 + 0.33 * i as f64, 3.0 - 0.27 * i as f64);
                        let p = [x, y, field.height_at(x, y) + [0.0, 0.05, 0.6][i % 3]];
                        let n = [[0.0, 0.0, 1.0], [0.3, -0.2, 0.933_380_951_166_24]][i % 2];
                        let got =
                            disk.visibility(None, Some(&pyramid), Planes { tangent: true, ground: None }, p, n, 0);
                        // The module doc's shares with the whole horizon.
                        let two_patches = 2.0 * disk.patch;
                        let covered = |sin_x: f64| (0.5 + sin_x / two_patches).clamp(0.0, 1.0);
                        let horizon = pyramid.horizon_along(p, disk.azimuth.unwrap(), f64::INFINITY);
                        let (sin_h, cos_h) = horizon.sin_cos();
                        let expected = disk.directions.map(|w| {
                            let (sin_e, cos_e) = (w[2], (1.0 - w[2] * w[2]).max(0.0).sqrt());
                            let cos_x = cos_h * cos_e + sin_h * sin_e;
                            let by_horizon = if cos_x < 0.0 { 1.0 } else { covered(sin_h * cos_e - cos_h * sin_e) };
                            1.0 - covered(-dot(n, w)).max(by_horizon)
                        });
                        assert_eq!(got.map(f64::to_bits), expected.map(f64::to_bits), "{axis:?} {p:?}");
                        match (got.iter().all(|&v| v == 0.0), got.iter().all(|&v| v == 1.0)) {
                            (true, _) => hidden += 1,
                            (_, true) => open += 1,
                            _ => partly += 1,
                        }
                    }
                }
            }
        }
        assert!(partly > 0 && hidden > 0 && open > 0, "partly {partly}, hidden {hidden}, open {open}");
    }

    /// The closed form against counting a fine uniform spiral of directions over cap `a`.
    #[test]
    fn cap_overlap_matches_counting() {
        let count = 400_000;
        for (a, b, gamma) in
            [(0.3f64, 0.2, 0.35f64), (0.05, 0.5, 0.5), (0.8, 0.8, 1.2), (1.2, 0.4, 1.0), (0.1, 0.1, 0.15)]
        {
            let golden = PI * (3.0 - 5f64.sqrt());
            let one_minus_cos = 1.0 - f64::cos(a);
            let axis_b = [gamma.sin(), 0.0, gamma.cos()];
            let inside = (0..count)
                .filter(|&i| {
                    let z = 1.0 - one_minus_cos * (i as f64 + 0.5) / count as f64;
                    let s = (1.0 - z * z).sqrt();
                    let phi = golden * i as f64;
                    let w = [s * phi.cos(), s * phi.sin(), z];
                    dot(w, axis_b) > f64::cos(b)
                })
                .count();
            let counted = 2.0 * PI * one_minus_cos * inside as f64 / count as f64;
            let closed = cap_overlap(a, b, gamma);
            assert!(
                (counted - closed).abs() < 1e-4 * 2.0 * PI * one_minus_cos + 1e-7,
                "{a} {b} {gamma}: {counted} vs {closed}"
            );
        }
    }

    /// A sun half behind a sphere: the disk's visible share against the closed-form cap
    /// overlap, within the pattern's resolution.
    #[test]
    fn disk_behind_a_sphere_matches_the_cap_overlap() {
        let half_angle = 4f64.to_radians();
        let light = SunLight { direction: [0.0, 0.0, 1.0], half_angle, strength: 1.0, color: [1.0; 3] };
        let disk = SunDisk::new(&light);
        let distance = 10.0;
        for (offset, radius) in [(0.0, 0.3), (0.5, 0.6), (0.7, 0.4), (0.9, 0.2), (0.3, 1.5)] {
            let tree = BlockerTree::new(&[Sphere::new([offset, 0.0, distance], radius)], 0.0);
            let v =
                disk.seen(Casters::Spheres(&tree), DiskHorizon::None, None, [0.0; 3], [0.0, 0.0, 1.0], 0).visibility();
            let visible = v.iter().sum::<f64>() / DISK_DIRECTIONS as f64;
            let cap = (radius / distance.hypot(offset)).asin();
            let gamma = (offset / distance).atan();
            let disk_solid_angle = 2.0 * PI * (1.0 - half_angle.cos());
            let expected = 1.0 - cap_overlap(half_angle, cap, gamma) / disk_solid_angle;
            assert!(
                (visible - expected).abs() < 0.04,
                "offset {offset}, radius {radius}: visible {visible:.3}, closed form {expected:.3}"
            );
        }
    }
}
