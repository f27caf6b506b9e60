//! The light: an environment map, a constant colour, or SH coefficients.
//!
//! # Environment map orientation
//!
//! Maps are equirectangular and oriented exactly as a Blender World's Environment Texture
//! with default mapping, so that results compare with Cycles. Cycles maps a world
//! direction `d` to texture coordinates with `direction_to_equirectangular` in
//! `intern/cycles/kernel/camera/projection.h` (blender/blender):
//! `direction_to_equirectangular_range(d, (-2 pi, pi, -pi, pi))`, i.e.
//!
//! ```text
//! u = (atan2(d.y, d.x) - pi) / (-2 pi) = 0.5 - atan2(d.y, d.x) / (2 pi)
//! v = (acos(d.z / |d|) - pi) / (-pi)   = 1 - acos(d.z) / pi
//! ```
//!
//! and the environment texture node looks the image up at `(u, v)` with `v = 0` at the
//! bottom of the image (Blender stores images bottom-up, flipping EXR files on load). So:
//! - the **first scan line of the file (top row) is the zenith** (+Z), the last the nadir;
//! - the centre column (`u = 0.5`) looks along +X, `u = 0.25` along +Y, `u = 0.75` along
//!   -Y, and the left and right edges along -X; in the image, azimuth increases to the
//!   left.
//!
//! Texel `(i, j)` (column `i`, row `j` from the top) of a `W x H` map is centred at
//! `u = (i + 0.5) / W`, `v = 1 - (j + 0.5) / H` and covers the exact solid angle
//! `(2 pi / W) (cos(pi j / H) - cos(pi (j + 1) / H))`. Lookups are bilinear between texel
//! centres, periodic in `u` and clamped in `v`.

use super::error::{check_image_size, SceneError};
use super::exr_read::ExrChannels;
use crate::sh::eval_basis;
use crate::sh::quadrature::gauss_legendre_on;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Cycles' `direction_to_equirectangular` (see the module doc): `(u, v)` of a direction,
/// `u` in `[0, 1]` left to right, `v` in `[0, 1]` bottom to top.
pub fn direction_to_equirectangular(dir: [f64; 3]) -> [f64; 2] {
    let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    if len == 0.0 {
        return [0.0, 0.0];
    }
    let u = (dir[1].atan2(dir[0]) - PI) / (-2.0 * PI);
    let v = ((dir[2] / len).clamp(-1.0, 1.0).acos() - PI) / (-PI);
    [u, v]
}

/// [`direction_to_equirectangular`] for map lookups, which need a small fraction of a
/// texel: the polar angle `acos(d.z / |d|)` as `atan2(|d.xy|, d.z)` (the same angle
/// without the division) and both angles by [`atan2_fast`], to 1e-8 rad (1.3e-5 of a
/// texel of a 8192-wide map). Every map lookup of a frame, per pixel, goes through here.
#[inline(always)]
pub fn lookup_coordinates(dir: [f64; 3]) -> [f64; 2] {
    let horizontal = (dir[0] * dir[0] + dir[1] * dir[1]).sqrt();
    if horizontal == 0.0 && dir[2] == 0.0 {
        return [0.0, 0.0];
    }
    let u = (atan2_fast(dir[1], dir[0]) - PI) / (-2.0 * PI);
    let v = (atan2_fast(horizontal, dir[2]) - PI) / (-PI);
    [u, v]
}

/// `atan2(y, x)` to 1e-8 rad (measured against libm around the circle): `atan(a)` for
/// `a = min(|x|, |y|) / max(|x|, |y|)` in `[0, 1]` as `a p(a^2)`, `p` the degree-8
/// polynomial interpolating `atan(sqrt t) / sqrt t` at 9 Chebyshev nodes of `[0, 1]`
/// (evaluated by Estrin's scheme, for a short dependency chain), then reflected into the
/// octant of `(x, y)`. `atan2(0, 0)` is 0; the sign of a zero `y` is not kept (a map
/// lookup wraps `-pi` and `pi` to the same column).
#[inline]
pub fn atan2_fast(y: f64, x: f64) -> f64 {
    const P: [f64; 9] = [
        0.999_999_981_788_655_8,
        -0.333_330_367_092_865_34,
        0.199_918_720_291_067_94,
        -0.141_977_977_940_324_52,
        0.106_183_706_366_642_9,
        -0.074_568_548_252_708_38,
        0.042_137_623_579_564_65,
        -0.015_731_249_115_826_518,
        0.002_766_283_500_090_193_7,
    ];
    let (ay, ax) = (y.abs(), x.abs());
    let (high, low) = if ay > ax { (ay, ax) } else { (ax, ay) };
    if !(high > 0.0) {
        return if high == 0.0 { 0.0 } else { f64::NAN };
    }
    let a = low / high;
    let t = a * a;
    let (t2, t4) = (t * t, t * t * t * t);
    let pair = |k: usize| P[k] + P[k + 1] * t;
    let p = (pair(0) + t2 * pair(2)) + t4 * ((pair(4) + t2 * pair(6)) + t4 * P[8]);
    let mut angle = p * a;
    if ay > ax {
        angle = std::f64::consts::FRAC_PI_2 - angle;
    }
    if x < 0.0 {
        angle = PI - angle;
    }
    if y < 0.0 {
        -angle
    } else {
        angle
    }
}

/// Inverse of [`direction_to_equirectangular`] (Cycles' `equirectangular_to_direction`).
pub fn equirectangular_to_direction(u: f64, v: f64) -> [f64; 3] {
    let phi = -2.0 * PI * u + PI;
    let theta = -PI * v + PI;
    [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]
}

/// An equirectangular radiance map in linear RGB.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentMap {
    pub file: PathBuf,
    pub width: usize,
    pub height: usize,
    /// `texels[row * width + column]`, row 0 the top (zenith) row.
    pub texels: Vec<[f32; 3]>,
}

impl EnvironmentMap {
    /// Reads an EXR (channels `R`, `G`, `B` in any part, or `<layer>.R/G/B` of a single
    /// layer, or one single channel as grey) or, for a `.hdr` file, a Radiance HDR image.
    /// Every texel must be finite and `>= 0`.
    pub fn read(file: &Path) -> Result<EnvironmentMap, SceneError> {
        let is_hdr = file.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("hdr"));
        let map = if is_hdr { Self::read_hdr(file)? } else { Self::read_exr(file)? };
        for (i, t) in map.texels.iter().enumerate() {
            if t.iter().any(|v| !v.is_finite()) {
                return Err(SceneError::NonFinite {
                    file: file.to_path_buf(),
                    what: format!("texel ({}, {})", i % map.width, i / map.width),
                });
            }
            if t.iter().any(|&v| v < 0.0) {
                return Err(SceneError::invalid(
                    file,
                    format!("texel ({}, {}) has negative radiance {t:?}", i % map.width, i / map.width),
                ));
            }
        }
        Ok(map)
    }

    fn read_exr(file: &Path) -> Result<EnvironmentMap, SceneError> {
        let mut exr = ExrChannels::read(file, "the environment map")?;
        let names: [String; 3] = if exr.has("R") && exr.has("G") && exr.has("B") {
            ["R".into(), "G".into(), "B".into()]
        } else {
            let prefixes: Vec<&str> = exr.directory.names.iter().filter_map(|n| n.strip_suffix(".R")).collect();
            let with_rgb: Vec<&str> =
                prefixes.into_iter().filter(|p| exr.has(&format!("{p}.G")) && exr.has(&format!("{p}.B"))).collect();
            match with_rgb.as_slice() {
                [p] => [format!("{p}.R"), format!("{p}.G"), format!("{p}.B")],
                [] if exr.directory.names.len() == 1 => {
                    let n = exr.directory.names[0].clone();
                    [n.clone(), n.clone(), n]
                }
                _ => {
                    return Err(SceneError::MissingChannel {
                        file: file.to_path_buf(),
                        channel: "R\", \"G\", \"B".into(),
                        found: exr.directory.names.clone(),
                    })
                }
            }
        };
        exr.use_size_of(&names[0]);
        let r = exr.take(file, &names[0])?;
        let g = exr.take(file, &names[1])?;
        let b = exr.take(file, &names[2])?;
        let texels = (0..r.len()).map(|i| [r[i], g[i], b[i]]).collect();
        Ok(EnvironmentMap { file: file.to_path_buf(), width: exr.width, height: exr.height, texels })
    }

    fn read_hdr(file: &Path) -> Result<EnvironmentMap, SceneError> {
        let f = std::fs::File::open(file).map_err(|e| SceneError::io(file, "the environment map", e))?;
        let bad = |e: image::ImageError| SceneError::Image { file: file.to_path_buf(), message: e.to_string() };
        let decoder = image::codecs::hdr::HdrDecoder::new(std::io::BufReader::new(f)).map_err(bad)?;
        let meta = decoder.metadata();
        check_image_size(file, meta.width as usize, meta.height as usize)?;
        let img = image::DynamicImage::from_decoder(decoder).map_err(bad)?.to_rgb32f();
        let (width, height) = (img.width() as usize, img.height() as usize);
        let texels = img.pixels().map(|p| [p[0], p[1], p[2]]).collect();
        Ok(EnvironmentMap { file: file.to_path_buf(), width, height, texels })
    }

    /// Exact solid angle of a texel of row `row`.
    pub fn texel_solid_angle(&self, row: usize) -> f64 {
        let t0 = PI * row as f64 / self.height as f64;
        let t1 = PI * (row + 1) as f64 / self.height as f64;
        2.0 * PI / self.width as f64 * (t0.cos() - t1.cos())
    }

    /// The map whose radiance along `d` is this map's along `m d` (`m` a rotation), as a
    /// Blender Mapping node of type Point with rotation `m` in front of the Environment
    /// Texture makes it: each texel is this map's bilinear lookup at its centre's rotated
    /// direction (one resampling, which spreads a one-texel feature over its neighbours
    /// and keeps its power to within a few percent).
    pub fn rotated(&self, m: &[[f64; 3]; 3]) -> EnvironmentMap {
        let (width, height) = (self.width, self.height);
        let texels = (0..width * height)
            .into_par_iter()
            .map(|i| {
                let (c, r) = (i % width, i / width);
                let d = equirectangular_to_direction(
                    (c as f64 + 0.5) / width as f64,
                    1.0 - (r as f64 + 0.5) / height as f64,
                );
                self.lookup(rotate(m, d))
            })
            .collect();
        EnvironmentMap { file: self.file.clone(), width, height, texels }
    }

    /// This map behind a Blender Mapping node of rotation `rotation` (Euler XYZ, degrees),
    /// then turned by `turn` degrees about Z (`--light-rotation`: the radiance along `d`
    /// is what was along `Rz(-turn) d`); the map itself when both are zero.
    pub fn oriented(self, rotation: [f64; 3], turn: f64) -> EnvironmentMap {
        if rotation == [0.0; 3] && turn == 0.0 {
            return self;
        }
        if rotation[0] == 0.0 && rotation[1] == 0.0 {
            return self.turned_about_z(rotation[2].rem_euclid(360.0) - turn.rem_euclid(360.0));
        }
        let mapping = euler_xyz(rotation.map(f64::to_radians));
        let turned = euler_xyz([0.0, 0.0, -turn.to_radians()]);
        let m = [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| mapping[i][k] * turned[k][j]).sum::<f64>()));
        self.rotated(&m)
    }

    /// [`Self::rotated`] for a rotation by `degrees` about Z: every texel centre keeps its
    /// row, so the bilinear lookup is a linear one along the row, at one shift for every
    /// texel (the same reads and weights, without a direction per texel). `degrees` is
    /// within a turn or two of 0 (the caller reduces its angles), so the shift is exact.
    fn turned_about_z(&self, degrees: f64) -> EnvironmentMap {
        let width = self.width;
        // The lookup of column c's centre turned by `degrees` falls at x = c - shift.
        let shift = (degrees / 360.0 * width as f64).rem_euclid(width as f64);
        let back = shift.ceil();
        let t = (back - shift) as f32;
        let back = back as usize % width;
        let texels = self
            .texels
            .par_chunks_exact(width)
            .flat_map_iter(|row| {
                (0..width).map(move |c| {
                    let (a, b) = (row[(c + width - back) % width], row[(c + width - back + 1) % width]);
                    [0, 1, 2].map(|k| a[k] * (1.0 - t) + b[k] * t)
                })
            })
            .collect();
        EnvironmentMap { file: self.file.clone(), width, height: self.height, texels }
    }

    /// Bilinear lookup in direction `dir` (need not be unit).
    pub fn lookup(&self, dir: [f64; 3]) -> [f32; 3] {
        self.lookup_at(lookup_coordinates(dir))
    }

    /// Bilinear lookup at the lookup coordinates `[u, v]` of a direction
    /// ([`lookup_coordinates`]).
    #[inline(always)]
    pub fn lookup_at(&self, coordinates: [f64; 2]) -> [f32; 3] {
        BilinearTaps::at(self.width, self.height, coordinates)
            .read(|column, row| self.texels[row * self.width + column])
    }
}

/// The texels a bilinear read of a `width` x `height` equirectangular map blends: two
/// columns (wrapping), two rows (clamped), and the weights of the second of each.
#[derive(Clone, Copy, Debug)]
pub struct BilinearTaps {
    pub columns: [usize; 2],
    pub rows: [usize; 2],
    pub tx: f32,
    pub ty: f32,
}

impl BilinearTaps {
    /// The taps in direction `dir` (need not be unit).
    #[inline(always)]
    pub fn new(width: usize, height: usize, dir: [f64; 3]) -> Self {
        Self::at(width, height, lookup_coordinates(dir))
    }

    /// The taps at lookup coordinates `[u, v]` ([`lookup_coordinates`]).
    #[inline(always)]
    pub fn at(width: usize, height: usize, [u, v]: [f64; 2]) -> Self {
        let x = u * width as f64 - 0.5;
        let y = ((1.0 - v) * height as f64 - 0.5).clamp(0.0, (height - 1) as f64);
        // Floors by truncation (x >= -1/2, y >= 0), and columns wrapped by a comparison:
        // u in [0, 1] puts them in [-1, width] (the same values as `floor` and
        // `rem_euclid`, which a pixel paid an integer division and two calls for).
        let x0 = x as i64 - i64::from(x < 0.0 && x != (x as i64) as f64);
        let r0 = y as usize;
        let w = width as i64;
        let col = |c: i64| {
            let wrapped = if c < 0 {
                c + w
            } else if c >= w {
                c - w
            } else {
                c
            };
            if (0..w).contains(&wrapped) {
                wrapped as usize
            } else {
                c.rem_euclid(w) as usize
            }
        };
        Self {
            columns: [col(x0), col(x0 + 1)],
            rows: [r0, (r0 + 1).min(height - 1)],
            tx: (x - x0 as f64) as f32,
            ty: (y - r0 as f64) as f32,
        }
    }

    /// The blend of `texel(column, row)` over the taps.
    #[inline(always)]
    pub fn read(&self, texel: impl Fn(usize, usize) -> [f32; 3]) -> [f32; 3] {
        let ([c0, c1], [r0, r1]) = (self.columns, self.rows);
        self.blend([texel(c0, r0), texel(c1, r0), texel(c0, r1), texel(c1, r1)])
    }

    /// The blend of the texels at the taps, in the order (column 0, row 0), (column 1,
    /// row 0), (column 0, row 1), (column 1, row 1).
    #[inline(always)]
    pub fn blend(&self, [a, b, c, d]: [[f32; 3]; 4]) -> [f32; 3] {
        let (tx, ty) = (self.tx, self.ty);
        let mut out = [0.0f32; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let top = a[k] * (1.0 - tx) + b[k] * tx;
            let bottom = c[k] * (1.0 - tx) + d[k] * tx;
            *o = top * (1.0 - ty) + bottom * ty;
        }
        out
    }
}

/// Highest order of an `sh` light in scene.json, and in a transfer header, which records
/// the light whole (its background and mirrors read every coefficient).
pub const MAX_SH_LIGHT_ORDER: usize = 64;

/// A CRC-32 of `file`'s bytes, `None` where it cannot be read.
pub fn file_crc(file: &Path) -> Option<u32> {
    std::fs::read(file).ok().map(|bytes| crc32fast::hash(&bytes))
}

/// An `sh` light (RGB coefficients, `order^2` of them) turned `degrees` about Z, as
/// `--light-rotation` turns a map: what lay at azimuth `a` lies at `a + degrees`
/// ([`crate::sh::rotation::rotate_z`], exact up to rounding).
pub fn turned_sh(coefficients: &[[f64; 3]], degrees: f64) -> Vec<[f64; 3]> {
    let order = (coefficients.len() as f64).sqrt().round() as usize;
    let mut turned = coefficients.to_vec();
    for k in 0..3 {
        let mut channel: Vec<f64> = turned.iter().map(|c| c[k]).collect();
        crate::sh::rotation::rotate_z(order, &mut channel, degrees.to_radians());
        for (c, x) in turned.iter_mut().zip(channel) {
            c[k] = x;
        }
    }
    turned
}

/// The rotation matrix of Euler angles `angles` (radians) in Blender's XYZ order, as the
/// Mapping node and object rotations use them: `R = Rz Ry Rx`.
pub fn euler_xyz(angles: [f64; 3]) -> [[f64; 3]; 3] {
    let (sx, cx) = angles[0].sin_cos();
    let (sy, cy) = angles[1].sin_cos();
    let (sz, cz) = angles[2].sin_cos();
    [
        [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
        [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
        [-sy, cy * sx, cy * cx],
    ]
}

/// `m v`.
pub fn rotate(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    m.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
}

/// Most sharp lights (suns and point lamps together) a scene may hold (each costs every
/// pixel a disk test).
pub const MAX_SUNS: usize = 16;

/// A distant light of finite angular size, in Blender's Sun lamp units: a uniform disk of
/// half-angle `half_angle` about `direction` whose irradiance on a surface facing it is
/// `strength * color` (so its radiance is `strength color / (pi sin^2 half_angle)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunLight {
    /// Unit vector towards the sun's centre.
    pub direction: [f64; 3],
    /// Radians, in `(0, pi/2]`.
    pub half_angle: f64,
    /// W/m^2 on a surface facing the sun.
    pub strength: f32,
    pub color: [f32; 3],
}

impl SunLight {
    /// `integral over the disk of L dw`, RGB: radiance times the disk's solid angle,
    /// `strength color 2 pi (1 - cos a) / (pi sin^2 a) = strength color 2 / (1 + cos a)`.
    /// The light a surface reflects is this times the mean of `V * BRDF` over directions
    /// spread uniformly on the disk.
    pub fn disk_integral(&self) -> [f64; 3] {
        let k = 2.0 / (1.0 + self.half_angle.cos()) * f64::from(self.strength);
        self.color.map(|c| k * f64::from(c))
    }

    /// Where the sun is, in degrees: its azimuth from +X towards +Y, and its elevation
    /// above the XY plane (Blender's world is Z-up).
    pub fn azimuth_elevation(&self) -> [f64; 2] {
        let [x, y, z] = self.direction;
        [y.atan2(x).to_degrees(), z.clamp(-1.0, 1.0).asin().to_degrees()]
    }

    /// The sun turned `degrees` about Z, as `--light-rotation` turns the light (whole turns
    /// taken out first, exactly).
    pub fn turned(&self, degrees: f64) -> SunLight {
        let turn = euler_xyz([0.0, 0.0, (degrees % 360.0).to_radians()]);
        SunLight { direction: rotate(&turn, self.direction), ..*self }
    }
}

/// A Blender Point lamp: a sphere of radius `radius` about `position` that emits `power`
/// watts (Blender's Point "Power") in `color`, uniformly, so that its radiance is `power
/// color / (4 pi^2 radius^2)` and a surface `d` away facing it receives `power color / (4
/// pi d^2)` (paper 002 treats such local spherical lights). Cycles (Blender 5.0) renders
/// a white plane under one within 1 % of these figures, either way.
///
/// With Blender's Soft Falloff (on by default), Cycles shades the lamp as a disk of the
/// same radius and radiance facing the receiver: its cone has `tan(half-angle) = radius /
/// d` instead of `sin(half-angle) = radius / d`. Far from the lamp the two agree; at
/// twice the radius the disk gives 20 % less light, and at the lamp's surface half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    pub position: [f64; 3],
    /// Metres, `>= 0` (0: a true point).
    pub radius: f64,
    /// Watts.
    pub power: f32,
    pub color: [f32; 3],
    /// Blender's Soft Falloff: the lamp is a disk facing the receiver.
    pub soft_falloff: bool,
}

/// The nearest a receiver is taken to be to a point lamp of radius 0, in metres: its
/// irradiance `power / (4 pi d^2)` stays finite at the lamp's position.
pub const POINT_NEAREST: f64 = 1e-6;

impl PointLight {
    /// The lamp as seen from `p`: the disk it covers, as a [`SunLight`] in Sun units
    /// (direction towards the centre, its half-angle, and the irradiance it gives a
    /// surface facing it), and the distance to its centre, beyond which nothing shadows
    /// it. From inside a lamp without Soft Falloff, the disk is the whole hemisphere about
    /// the direction to the centre (the normal's side when `p` is the centre itself).
    pub fn seen_from(&self, p: [f64; 3], n: [f64; 3]) -> (SunLight, f64) {
        let d = [0, 1, 2].map(|k| self.position[k] - p[k]);
        let distance2 = d.iter().map(|c| c * c).sum::<f64>();
        let distance = distance2.sqrt();
        let direction = if distance > 0.0 { d.map(|c| c / distance) } else { n };
        let r2 = self.radius * self.radius;
        let d2 = distance2.max(POINT_NEAREST * POINT_NEAREST);
        // sin^2 of the half-angle, and the area the irradiance spreads over (per 4 pi).
        let (sin2, spread) =
            if self.soft_falloff { (r2 / (d2 + r2), d2 + r2) } else { ((r2 / d2).min(1.0), d2.max(r2)) };
        let half_angle = sin2.sqrt().asin().max(POINT_HALF_ANGLE_MIN);
        let strength = (f64::from(self.power) / (4.0 * PI * spread)).min(f64::from(f32::MAX)) as f32;
        (SunLight { direction, half_angle, strength, color: self.color }, distance)
    }

    /// Where the ray from `origin` along unit `dir` meets the lamp (its sphere, or with
    /// Soft Falloff the disk through its centre facing `origin`, as Cycles intersects it),
    /// as a distance; `None` when it misses, or for a lamp of radius 0.
    pub fn hit_along(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<f64> {
        let to_centre = [0, 1, 2].map(|k| self.position[k] - origin[k]);
        let along: f64 = (0..3).map(|k| to_centre[k] * dir[k]).sum();
        let d2: f64 = to_centre.iter().map(|c| c * c).sum();
        let r2 = self.radius * self.radius;
        if !(self.radius > 0.0 && along > 0.0) {
            return None;
        }
        if self.soft_falloff {
            let t = d2 / along;
            (t * t - d2 <= r2).then_some(t)
        } else {
            let across2 = d2 - along * along;
            (across2 <= r2).then(|| if d2 > r2 { along - (r2 - across2).sqrt() } else { along + (r2 - across2).sqrt() })
        }
    }

    /// The lamp's radiance, `power color / (4 pi^2 radius^2)` (for a radius above 0).
    pub fn radiance(&self) -> [f32; 3] {
        let k = f64::from(self.power) / (4.0 * PI * PI * self.radius * self.radius);
        self.color.map(|c| (k * f64::from(c)).min(f64::from(f32::MAX)) as f32)
    }
}

/// The narrowest disk a point lamp is shaded as (radians): a lamp of radius 0, or one
/// far away, is a disk this wide, whose penumbra no pixel resolves.
pub const POINT_HALF_ANGLE_MIN: f64 = 1e-5;

/// The scene's light, ready to be projected or evaluated.
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// Map radiance times `strength`.
    Environment { map: EnvironmentMap, strength: f32 },
    /// The same radiance from every direction.
    Constant([f32; 3]),
    /// Coefficients in the crate's SH convention (`crate::sh::basis`), order^2 of them.
    Sh(Vec<[f64; 3]>),
}

/// What a light is made from, its files resolved (`Scene::light_source`), as a transfer
/// file's header records it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightSource {
    /// A map times `strength`, behind a Mapping rotation (Euler XYZ, degrees) and turned
    /// `turn` degrees about Z.
    Environment {
        file: PathBuf,
        strength: f32,
        rotation: [f64; 3],
        turn: f64,
    },
    Constant([f32; 3]),
    Sh(Vec<[f64; 3]>),
}

impl Light {
    /// Order-`order` SH projection (`order * order` RGB coefficients) of the radiance.
    ///
    /// - Map: each texel is taken as constant over its exact extent and the basis is
    ///   integrated over that extent (see [`project_texels`]), times `strength`.
    /// - Constant `c`: only the DC term, `c * 2 sqrt(pi)`.
    /// - `sh`: the given coefficients, truncated or padded with zeros.
    pub fn sh_coefficients(&self, order: usize) -> Vec<[f64; 3]> {
        let count = order * order;
        match self {
            Light::Constant(c) => {
                let mut out = vec![[0.0; 3]; count];
                if count > 0 {
                    let k = 2.0 * PI.sqrt();
                    out[0] = [c[0] as f64 * k, c[1] as f64 * k, c[2] as f64 * k];
                }
                out
            }
            Light::Sh(v) => (0..count).map(|i| v.get(i).copied().unwrap_or([0.0; 3])).collect(),
            Light::Environment { map, strength } => {
                let mut out = project_texels(map, order);
                for c in &mut out {
                    for v in c.iter_mut() {
                        *v *= *strength as f64;
                    }
                }
                out
            }
        }
    }

    /// Radiance arriving from direction `dir` (pointing away from the receiver, towards
    /// the sky), for background pixels: bilinear map lookup times strength, the constant,
    /// or the SH expansion clamped to `>= 0`.
    pub fn radiance(&self, dir: [f64; 3]) -> [f32; 3] {
        match self {
            Light::Constant(c) => *c,
            Light::Environment { .. } => self.radiance_at(dir, lookup_coordinates(dir)),
            Light::Sh(v) => {
                let order = (v.len() as f64).sqrt().round() as usize;
                let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
                let d = [dir[0] / len, dir[1] / len, dir[2] / len];
                let mut y = vec![0.0f64; order * order];
                eval_basis(order, d, &mut y);
                let mut out = [0.0f32; 3];
                for (k, o) in out.iter_mut().enumerate() {
                    let s: f64 = v.iter().zip(&y).map(|(c, b)| c[k] * b).sum();
                    *o = s.max(0.0) as f32;
                }
                out
            }
        }
    }

    /// [`Self::radiance`] from direction `dir`, whose lookup coordinates
    /// ([`lookup_coordinates`]) are `coordinates`, for a caller that has them.
    #[inline(always)]
    pub fn radiance_at(&self, dir: [f64; 3], coordinates: [f64; 2]) -> [f32; 3] {
        match self {
            Light::Environment { map, strength } => {
                let l = map.lookup_at(coordinates);
                [l[0] * strength, l[1] * strength, l[2] * strength]
            }
            _ => self.radiance(dir),
        }
    }
}

/// Gauss-Legendre nodes per texel row for the integral in `z = cos(theta)`: exact for
/// the polynomial part of the basis through order 16; for odd `m` the factor
/// `sin^m(theta)` makes the pole rows slightly inexact (relative error below 1e-6 at
/// 32 rows).
const ROW_NODES: usize = 8;

/// Order-`order` projection of a map whose texels are constant over their extent:
/// `c_lm = sum over texels of L * integral over the texel of y_lm`.
///
/// The basis separates, `y_lm(z, phi) = Z_l^|m|(z) * {cos(m phi), 1, sin(|m| phi)}` for
/// `m > 0, = 0, < 0`, with `Z_l^|m|` the basis evaluated at `phi = 0`; so each texel's
/// integral is a row integral in `z` (Gauss-Legendre) times a column integral in `phi`
/// (closed form). Cost per row: `O(width * order + order^2)`. A constant map projects to
/// its DC term alone, to rounding.
pub fn project_texels(map: &EnvironmentMap, order: usize) -> Vec<[f64; 3]> {
    let count = order * order;
    let w = map.width;
    // Column c spans u in [c/W, (c+1)/W], i.e. phi = pi - 2 pi u in [pi - 2 pi (c+1)/W, pi - 2 pi c/W].
    let phi_edge = |c: usize| PI - 2.0 * PI * c as f64 / w as f64;
    // col_int[c][m] = integral of cos(m phi) (m >= 0) and sin(m phi) (m >= 1).
    let mut cos_int = vec![vec![0.0f64; order]; w];
    let mut sin_int = vec![vec![0.0f64; order]; w];
    for c in 0..w {
        let (lo, hi) = (phi_edge(c + 1), phi_edge(c));
        cos_int[c][0] = hi - lo;
        for m in 1..order {
            let mf = m as f64;
            cos_int[c][m] = ((mf * hi).sin() - (mf * lo).sin()) / mf;
            sin_int[c][m] = ((mf * lo).cos() - (mf * hi).cos()) / mf;
        }
    }
    (0..map.height)
        .into_par_iter()
        .map(|row| {
            // Row r spans theta in [pi r / H, pi (r+1) / H], z from cos(top) down to cos(bottom).
            let z_hi = (PI * row as f64 / map.height as f64).cos();
            let z_lo = (PI * (row + 1) as f64 / map.height as f64).cos();
            let mut zint = vec![0.0f64; count];
            let mut y = vec![0.0f64; count];
            for (z, wz) in gauss_legendre_on(ROW_NODES, z_lo, z_hi) {
                eval_basis(order, [(1.0 - z * z).max(0.0).sqrt(), 0.0, z], &mut y);
                for (a, b) in zint.iter_mut().zip(&y) {
                    *a += wz * b;
                }
            }
            // sums[m] = sum over columns of L * phi-integral, cosine (m >= 0) and sine parts.
            let mut cos_sum = vec![[0.0f64; 3]; order];
            let mut sin_sum = vec![[0.0f64; 3]; order];
            for c in 0..w {
                let l = map.texels[row * w + c];
                if l == [0.0; 3] {
                    continue;
                }
                for m in 0..order {
                    for k in 0..3 {
                        cos_sum[m][k] += l[k] as f64 * cos_int[c][m];
                        sin_sum[m][k] += l[k] as f64 * sin_int[c][m];
                    }
                }
            }
            let mut acc = vec![[0.0f64; 3]; count];
            for l in 0..order {
                for m in -(l as i32)..=(l as i32) {
                    let i = (l * (l + 1)) as i64 + m as i64;
                    let zpart = zint[(l * (l + 1)) + m.unsigned_abs() as usize];
                    let sums = if m < 0 { &sin_sum } else { &cos_sum };
                    for k in 0..3 {
                        acc[i as usize][k] = zpart * sums[m.unsigned_abs() as usize][k];
                    }
                }
            }
            acc
        })
        .reduce(
            || vec![[0.0f64; 3]; count],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(&b) {
                    for k in 0..3 {
                        x[k] += y[k];
                    }
                }
                a
            },
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`atan2_fast`] against libm's `atan2` on a fine polar grid of directions and on the
    /// axes, diagonals and zeros.
    #[test]
    fn atan2_fast_matches_libm() {
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let phi = -PI + 2.0 * PI * (i as f64 + 0.37) / 200_000.0;
            for r in [1e-300, 0.3, 7.0, 1e300] {
                let (y, x) = (r * phi.sin(), r * phi.cos());
                worst = worst.max((atan2_fast(y, x) - y.atan2(x)).abs());
            }
        }
        for (y, x) in [(0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0), (1.0, 1.0), (-1.0, -1.0), (2.0, -2.0)] {
            worst = worst.max((atan2_fast(y, x) - f64::atan2(y, x)).abs());
        }
        assert!(worst < 1.2e-8, "worst {worst:e} rad");
        assert_eq!(atan2_fast(0.0, 0.0), 0.0);
    }

    /// A turn about Z (a Mapping rotation about Z, `--light-rotation`) shifts the rows as
    /// the general resampling does: within 1e-5 of the map's range (the lookup's angles
    /// are good to 1e-8 rad), for turns that fall between columns, on them, negative and
    /// past a whole turn, on maps of even and odd width.
    #[test]
    fn a_turn_about_z_resamples_as_the_rotation_does() {
        for (width, height) in [(64, 32), (45, 20)] {
            let texels = (0..width * height)
                .map(|i| {
                    let (c, r) = ((i % width) as f32, (i / width) as f32);
                    [(0.37 * c).sin() + 1.5, (0.11 * c * r).cos() + 1.0, 0.02 * (c + 3.0 * r)]
                })
                .collect();
            let map = EnvironmentMap { file: "turned".into(), width, height, texels };
            for (z, turn) in [(0.0, 37.3), (0.0, -90.0), (12.5, 360.0), (0.0, 360.0 / width as f64), (-20.0, 0.1)] {
                let general = map.rotated(&euler_xyz([0.0, 0.0, (z - turn).to_radians()]));
                let shifted = map.clone().oriented([0.0, 0.0, z], turn);
                for (a, b) in general.texels.iter().zip(&shifted.texels) {
                    for k in 0..3 {
                        assert!((a[k] - b[k]).abs() < 1e-5, "{width}x{height}, turn {turn}: {a:?} against {b:?}");
                    }
                }
            }
            // Angles far beyond a turn are taken modulo 360 degrees, and stay finite.
            let far = map.clone().oriented([0.0, 0.0, 1e300], -3e300);
            assert!(far.texels.iter().all(|t| t.iter().all(|v| v.is_finite())));
        }
    }

    /// The lookup coordinates are Blender's mapping to 2e-9 in `u` and 4e-9 in `v`.
    #[test]
    fn lookup_coordinates_are_the_mapping() {
        for i in 0..20_000 {
            let z = -1.0 + 2.0 * (i as f64 + 0.5) / 20_000.0;
            let phi = 2.4 * i as f64;
            let s = (1.0 - z * z).sqrt();
            let d = [3.0 * s * phi.cos(), 3.0 * s * phi.sin(), 3.0 * z];
            let ([u, v], [eu, ev]) = (lookup_coordinates(d), direction_to_equirectangular(d));
            let du = (u - eu).abs().min(1.0 - (u - eu).abs());
            assert!(du < 2e-9 && (v - ev).abs() < 4e-9, "{d:?}: {u} {v} against {eu} {ev}");
        }
    }
}
