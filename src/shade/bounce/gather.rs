//! The gather: the radiance the lit surroundings send to each receiver, in SH of
//! [`ORDER`] per channel, and what each pixel reflects of it (module doc of [`super`]).

use super::*;

impl Surroundings {
    pub(super) fn point_count(&self) -> usize {
        self.terrain.as_ref().map_or(0, |t| t.side * t.side) + self.spheres.len() * SPHERE_DIRECTIONS
    }

    /// Sets the light of the secondary points, in [`SurroundingsPlan::points`]' order: a
    /// texel's radiance, a sphere's point's irradiance over pi ([`SphereLight::reflect`]);
    /// a sphere's point under the terrain is left out (`None`).
    pub(super) fn set_light(&mut self, light: &[[f32; 3]]) {
        let finite = |c: [f32; 3]| c.map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 });
        let mut next = 0;
        if let Some(grid) = &mut self.terrain {
            let texels = grid.side * grid.side;
            grid.radiance = light[..texels].iter().map(|&c| finite(c)).collect();
            next = texels;
        }
        let terrain = &self.terrain;
        for sphere in &mut self.spheres {
            let irradiance = std::array::from_fn(|k| {
                let m = sphere_direction(k);
                let p: [f64; 3] = std::array::from_fn(|a| sphere.centre[a] + sphere.radius * m[a]);
                let buried = terrain.as_ref().is_some_and(|t| p[2] < t.height(p[0], p[1]));
                (!buried).then(|| finite(light[next + k]))
            });
            sphere.reflect(irradiance);
            next += SPHERE_DIRECTIONS;
        }
    }

    /// The bounce radiance incident at `p` with unit normal `n` (SH per [`CHANNELS`]),
    /// from the terrain and from the blockers; `object`: the receiver's own object, whose
    /// spheres it does not see.
    pub(super) fn incident(&self, p: [f64; 3], n: [f64; 3], object: u32) -> [Incident; 2] {
        let mut terrain = [[0.0f64; COUNT]; CHANNELS];
        if let Some(grid) = &self.terrain {
            let mut slices = [[0.0f64; ORDER]; CHANNELS * AZIMUTHS];
            grid.add_slices(p, &mut slices);
            let mut by_channel = [[0.0f64; ORDER * AZIMUTHS]; CHANNELS];
            for k in 0..AZIMUTHS {
                for c in 0..CHANNELS {
                    by_channel[c][k * ORDER..(k + 1) * ORDER].copy_from_slice(&slices[CHANNELS * k + c]);
                }
            }
            for c in 0..CHANNELS {
                self.turn.accumulate(&by_channel[c], &mut terrain[c]);
            }
        }
        let mut blockers = [[0.0f64; COUNT]; CHANNELS];
        let mut cap = [0.0f64; ORDER];
        for sphere in &self.spheres {
            if object != 0 && sphere.object == object {
                continue;
            }
            let to: [f64; 3] = std::array::from_fn(|a| sphere.centre[a] - p[a]);
            let distance = dot(to, to).sqrt();
            // A cap under 1e-4 of the sphere of directions (radius under a hundredth of its
            // distance) reflects less than that share of its radiance.
            if distance <= sphere.radius || dot(to, n) <= 0.0 || sphere.radius < 0.01 * distance {
                continue;
            }
            let direction = to.map(|v| v / distance);
            cap_log_zh(ORDER, 1.0, (sphere.radius / distance).asin(), &mut cap);
            let mut rotated = [0.0f64; COUNT];
            add_rotated_zonal(ORDER, &cap, sphere.overlap, direction, &mut rotated);
            let [r, g, b] = sphere.radiance_towards(direction.map(|v| -v));
            for (channel, radiance) in blockers.iter_mut().zip([r, g, b, 1.0]) {
                for j in 0..COUNT {
                    channel[j] += radiance * rotated[j];
                }
            }
        }
        if let Some(sky) = &self.sky {
            terrain[OCCLUSION] = sky.weigh(&terrain[OCCLUSION]);
            blockers[OCCLUSION] = sky.weigh(&blockers[OCCLUSION]);
        }
        [terrain, blockers]
    }

    /// The radiance of the surroundings along the ray from `p` in unit direction `d`,
    /// split as the terrain's and the blockers': that of the nearest of the terrain and
    /// the spheres (not those of `object`) it meets; black where it meets neither.
    pub(super) fn along(&self, p: [f64; 3], d: [f64; 3], object: u32) -> [[f64; 3]; 2] {
        let mut nearest: Option<(f64, &SphereLight)> = None;
        for sphere in self.spheres.iter().filter(|s| object == 0 || s.object != object) {
            let Some(t) = ray_hits_sphere(p, d, sphere.centre, sphere.radius) else { continue };
            if nearest.is_none_or(|(best, _)| t < best) {
                nearest = Some((t, sphere));
            }
        }
        let terrain = self.terrain.as_ref().and_then(|grid| grid.hit(p, d).map(|(q, t)| (grid, q, t)));
        match (terrain, nearest) {
            (Some((grid, q, t)), sphere) if sphere.is_none_or(|(s, _)| t <= s) => {
                [grid.radiance_at(q[0], q[1]), [0.0; 3]]
            }
            (_, Some((t, sphere))) => {
                let hit: [f64; 3] = std::array::from_fn(|k| p[k] + t * d[k] - sphere.centre[k]);
                [[0.0; 3], sphere.radiance_towards(hit.map(|v| v / sphere.radius))]
            }
            _ => [[0.0; 3]; 2],
        }
    }

    /// The bounce irradiance (RGB) at `p` with unit normal `n`, from the terrain and from
    /// the blockers; `object`: the receiver's own object, whose spheres it does not see.
    /// `visibility`: the direct light's own visibility of the receiver (the
    /// `visibility` pass), which scales the bounce ([`leak_scale`]).
    pub fn irradiance(&self, p: [f64; 3], n: [f64; 3], object: u32, visibility: Option<f32>) -> [[f64; 3]; 2] {
        let mut y = [0.0f64; COUNT];
        eval_basis(ORDER, n, &mut y);
        let e = self.incident(p, n, object).map(|incident| convolved_with(&incident, &y, clamped_cosine_factor));
        let scales = self.leak_scales(visibility, &e, &y);
        std::array::from_fn(|part| std::array::from_fn(|c| scales[part] * e[part][c]))
    }

    /// The [`leak_scale`] of the terrain's and of the blockers' parts of the irradiances
    /// `e` at the normal whose basis is `y`: those the visibility pass covers, the height
    /// field and the blockers (the ground plane is the kernel's unoccluded hemisphere, and
    /// its bounce is not scaled). Their covered share is weighted by the sky as the
    /// visibility pass weighs it ([`SkyWeighting`]), by the cosine alone without a sky.
    pub(super) fn leak_scales(&self, visibility: Option<f32>, e: &[[f64; CHANNELS]; 2], y: &[f64; COUNT]) -> [f64; 2] {
        let field = self.terrain.as_ref().is_some_and(|t| t.field.is_some());
        let covered = if field { e[0][OCCLUSION] + e[1][OCCLUSION] } else { e[1][OCCLUSION] };
        let open = self.sky.as_ref().map_or(PI, |sky| sky.open(y));
        let scale = leak_scale(visibility, covered / open);
        [if field { scale } else { 1.0 }, scale]
    }

    /// The bounce light each pixel of `frame` reflects, by part: its diffuse albedo times
    /// `E / pi`, plus, for a glossy material, its specular colour times the incident
    /// radiance about the mirror direction, blurred by the Phong lobe of its exponent
    /// (band `l` scaled by `exp(-l^2 / 2s)`, the lobe's ZH for large `s`); black on water
    /// and the background.
    ///
    /// The incident radiance is gathered at every `stride`-th pixel of each row and column
    /// and interpolated between them, each pixel reflecting it with its own normal (NS09,
    /// Section 7: bounce light sub-sampled, shaded with full-resolution normals). A
    /// neighbour counts only if it lies on the same object, faces the same way and lies
    /// near the pixel's tangent plane (within `stride` pixel footprints); a pixel with no
    /// such neighbour gathers for itself, so edges and silhouettes stay sharp.
    ///
    /// `visibility`: the frame's `visibility` pass, which scales each pixel's diffuse
    /// bounce ([`leak_scale`]).
    pub fn indirect(&self, scene: &Scene, frame: &Frame, stride: usize, visibility: Option<&[f32]>) -> IndirectParts {
        let g = &frame.gbuffer;
        let receivers: Vec<Option<Receiver>> = (0..g.material.len())
            .into_par_iter()
            .map(|i| Receiver::of(scene, frame, i, visibility.map(|v| v[i])))
            .collect();
        let gather = |r: &Receiver| self.incident(r.point.position, r.point.normal, r.point.object);
        // World size of a pixel per unit of distance from the eye.
        let footprint = frame.camera.as_ref().map(|c| c.sensor_width_mm / c.lens_mm / g.width as f64);
        let (width, height) = (g.width, g.height);
        let stride = if footprint.is_some() { stride.max(1) } else { 1 };
        let (columns, rows) = ((width - 1).div_ceil(stride) + 1, (height - 1).div_ceil(stride) + 1);
        let node_pixel = |gx: usize, gy: usize| (gy * stride).min(height - 1) * width + (gx * stride).min(width - 1);
        // Held in f32, which the interpolation below sums in vector lanes.
        let nodes: Vec<Option<[Incident32; 2]>> = if stride > 1 {
            (0..columns * rows)
                .into_par_iter()
                .map(|k| {
                    let receiver = receivers[node_pixel(k % columns, k / columns)].as_ref();
                    let incident = receiver.filter(|r| r.transmitted.is_none()).map(gather);
                    incident.map(|parts| parts.map(|part| part.map(|channel| channel.map(|v| v as f32))))
                })
                .collect()
        } else {
            Vec::new()
        };
        let (heightfield, blockers): (Vec<[f32; 3]>, Vec<[f32; 3]>) = (0..width * height)
            .into_par_iter()
            .map(|i| {
                let Some(r) = &receivers[i] else { return ([0.0; 3], [0.0; 3]) };
                if r.transmitted.is_some() {
                    let [terrain, spheres] = r.reflected(&[[[0.0; COUNT]; CHANNELS]; 2], self);
                    return (terrain, spheres);
                }
                let interpolated = (stride > 1).then(|| {
                    let (x, y) = (i % width, i / width);
                    let (gx, gy) = (x / stride, y / stride);
                    let scale = footprint.unwrap_or(0.0)
                        * stride as f64
                        * distance(r.point.position, r.point.view_origin).max(1e-9);
                    let mut sum = [[[0.0f32; COUNT]; CHANNELS]; 2];
                    let mut weights = 0.0;
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let (cx, cy) = ((gx + dx).min(columns - 1), (gy + dy).min(rows - 1));
                        let k = node_pixel(cx, cy);
                        let (Some(node), Some(neighbour)) = (&nodes[cy * columns + cx], &receivers[k]) else {
                            continue;
                        };
                        let along = |c: usize, p: usize, last: usize| {
                            let (lo, hi) = ((c * stride).min(last), ((c + 1) * stride).min(last));
                            if hi > lo {
                                (p - lo) as f64 / (hi - lo) as f64
                            } else {
                                0.0
                            }
                        };
                        let (fx, fy) = (along(gx, x, width - 1), along(gy, y, height - 1));
                        let bilinear = (if dx == 1 { fx } else { 1.0 - fx }) * (if dy == 1 { fy } else { 1.0 - fy });
                        let w = bilinear * r.likeness(neighbour, scale);
                        if w > 0.0 {
                            let w32 = w as f32;
                            for (part, from) in sum.iter_mut().zip(node) {
                                for (to, from) in part.iter_mut().zip(from) {
                                    for (t, f) in to.iter_mut().zip(from) {
                                        *t += w32 * f;
                                    }
                                }
                            }
                            weights += w;
                        }
                    }
                    (weights > 1e-3)
                        .then(|| sum.map(|part| part.map(|channel| channel.map(|v| f64::from(v) / weights))))
                });
                let incident = interpolated.flatten().unwrap_or_else(|| gather(r));
                let [terrain, spheres] = r.reflected(&incident, self);
                (terrain, spheres)
            })
            .unzip();
        IndirectParts { heightfield, blockers }
    }
}

/// A pixel that reflects bounce light, and how.
pub(super) struct Receiver {
    pub(super) point: SurfacePoint,
    pub(super) albedo: [f32; 3],
    pub(super) specular: [f32; 3],
    /// The Phong exponent of a glossy material.
    pub(super) exponent: Option<f64>,
    pub(super) mirror: [f64; 3],
    /// Water seen with Blender's colour passes: what its surface lets through of the
    /// terrain below it (`(1 - F) tint^2`), and the refracted direction.
    pub(super) transmitted: Option<([f32; 3], [f64; 3])>,
    /// The direct light's visibility of the point ([`leak_scale`]).
    pub(super) visibility: Option<f32>,
}

/// Water's index of refraction, as the exporter's water material has it.
pub(super) const WATER_IOR: f64 = 1.33;

/// A glossy lobe of exponent `s` reads the radiance traced along its mirror direction
/// with weight `(s - BLURRED_BELOW) / (s + SHARP_EXPONENT - BLURRED_BELOW)` (0 below
/// `BLURRED_BELOW`), the incident radiance blurred by the lobe with the rest: the
/// gather's order resolves nothing narrower than about 40 degrees, a lobe of exponent 8
/// (half width about 25 degrees) is as wide as that, and the trace is spared for it.
pub(super) const SHARP_EXPONENT: f64 = 50.0;
pub(super) const BLURRED_BELOW: f64 = 8.0;

/// The share of a Phong lobe of exponent `s` read as the cosine lobe about the normal
/// (`E / pi`), the rest as the incident radiance blurred about the mirror direction:
/// `1 / (1 + s)`, exact at both limits. The blur alone (`exp(-l^2 / 2s)`) is the narrow
/// lobe's limit; a broad one then reads the whole sphere, half of it below the tangent
/// plane where a receiver on the ground sees the ground, while Phong's BRDF at `s = 0`
/// is constant and weighs the incident radiance by the cosine alone. On a terrain of
/// Principled sand (`s` 0.26, specular 0.035) the bounce was 0.0264 against the 0.0161
/// Cycles' light paths add to its direct light (`sun_lamp`), 0.0187 with this share.
pub(super) fn broad_share(s: f64) -> f64 {
    1.0 / (1.0 + s.max(0.0))
}

impl Receiver {
    /// Pixel `i` of `frame`, `None` on the background, black materials and water without
    /// colour passes (a mirror of its tint, the converted material).
    pub(super) fn of(scene: &Scene, frame: &Frame, i: usize, visibility: Option<f32>) -> Option<Self> {
        let g = &frame.gbuffer;
        let material = scene.materials.get(&g.material[i])?;
        let point = crate::shade::frame::surface_at(g, i, None, frame);
        let mirror = crate::shade::point::reflect_view(point.view_origin, point.position, point.normal);
        let (albedo, specular) = match (material, g.colours_at(i)) {
            (Material::Water { tint }, Some((_, fresnel))) => {
                // The view ray crosses the surface once (`1 - F`, the tint), and the light
                // that lit the floor below crossed it too (the tint again; the grid shades
                // the floor as if dry): dunes against Cycles 0.0302 with the tint once,
                // 0.0234 with it twice, the water itself from 0.1 too bright to within noise.
                let through = std::array::from_fn(|c| (1.0 - fresnel[c]).clamp(0.0, 1.0) * tint[c] * tint[c]);
                let refracted = refract(point.view_origin, point.position, point.normal)?;
                let transmitted = Some((through, refracted));
                let (albedo, specular) = ([0.0; 3], [0.0; 3]);
                return Some(Self { point, albedo, specular, exponent: None, mirror, transmitted, visibility });
            }
            (Material::Water { .. }, None) => return None,
            (_, Some(colours)) => colours,
            (m, None) => m.pass_colours(),
        };
        let exponent = match material {
            Material::Phong { exponent, .. } if specular != [0.0; 3] => Some(f64::from(*exponent)),
            _ => None,
        };
        if albedo == [0.0; 3] && exponent.is_none() {
            return None;
        }
        Some(Self { point, albedo, specular, exponent, mirror, transmitted: None, visibility })
    }

    /// How far `other`'s gathered radiance stands for this receiver's, in `[0, 1]`: 0
    /// on another object or facing another way, falling off with the distance between
    /// `other` and this receiver's tangent plane in units of `scale`.
    pub(super) fn likeness(&self, other: &Receiver, scale: f64) -> f64 {
        let (a, b) = (&self.point, &other.point);
        let facing = dot(a.normal, b.normal);
        if a.object != b.object || facing < 0.9 {
            return 0.0;
        }
        let offset: [f64; 3] = std::array::from_fn(|k| b.position[k] - a.position[k]);
        let off_plane = dot(offset, a.normal).abs() / scale.max(1e-12);
        ((facing - 0.9) / 0.1) / (1.0 + off_plane * off_plane)
    }

    /// The radiance this receiver sends towards the eye of the bounce light, by part:
    /// `incident` gathered for it (terrain, blockers), and what it traces itself (the
    /// mirror direction of a glossy lobe, the refracted ray of water).
    pub(super) fn reflected(&self, incident: &[Incident; 2], surroundings: &Surroundings) -> [[f32; 3]; 2] {
        let point = &self.point;
        if let Some((through, refracted)) = self.transmitted {
            let [terrain, blockers] = surroundings.along(point.position, refracted, point.object);
            let seen = |l: [f64; 3]| std::array::from_fn(|c| through[c] * l[c] as f32);
            return [seen(terrain), seen(blockers)];
        }
        let mut y = [0.0f64; COUNT];
        eval_basis(ORDER, point.normal, &mut y);
        let e = incident.map(|part| convolved_with(&part, &y, clamped_cosine_factor));
        let scales = surroundings.leak_scales(self.visibility, &e, &y);
        let glossy = self.exponent.map(|s| {
            let sharp = ((s - BLURRED_BELOW) / (s + SHARP_EXPONENT - BLURRED_BELOW)).max(0.0);
            let along =
                if sharp > 0.0 { surroundings.along(point.position, self.mirror, point.object) } else { [[0.0; 3]; 2] };
            let mut y = [0.0f64; COUNT];
            eval_basis(ORDER, self.mirror, &mut y);
            let lobe = |l: usize| (-((l * l) as f64) / (2.0 * s)).exp();
            let blurred = incident.map(|part| convolved_with(&part, &y, lobe));
            let broad = broad_share(s);
            std::array::from_fn::<[f64; 3], 2, _>(|part| {
                std::array::from_fn(|c| {
                    let read = (1.0 - broad) * blurred[part][c] + broad * e[part][c] / PI;
                    sharp * along[part][c] + (1.0 - sharp) * read
                })
            })
        });
        std::array::from_fn(|part| {
            let e = e[part].map(|v| scales[part] * v);
            let glossy = glossy.map_or([0.0; 3], |g| g[part]);
            std::array::from_fn(|c| self.albedo[c] * (e[c] / PI) as f32 + self.specular[c] * glossy[c] as f32)
        })
    }
}

/// The direction a view ray from `eye` through `p` takes into water of normal `n`
/// (Snell's law, [`WATER_IOR`]); `None` for a ray that meets the surface from below.
pub(super) fn refract(eye: [f64; 3], p: [f64; 3], n: [f64; 3]) -> Option<[f64; 3]> {
    let d: [f64; 3] = std::array::from_fn(|k| p[k] - eye[k]);
    let length = dot(d, d).sqrt();
    let v = d.map(|x| x / length.max(1e-300));
    let cos_in = -dot(v, n);
    if !(cos_in > 0.0) {
        return None;
    }
    let eta = 1.0 / WATER_IOR;
    let k = 1.0 - eta * eta * (1.0 - cos_in * cos_in);
    let scale = eta * cos_in - k.sqrt();
    Some(std::array::from_fn(|i| eta * v[i] + scale * n[i]))
}

/// The sky's luminance as the direct light's visibility pass weighs its directions (the
/// kernel's SH light, [`crate::shade::plan::environment_luminance`]), for the covered
/// share [`leak_scale`] compares with the light the visibility lets through.
///
/// The visibility pass is `lum(exp*(V + D) . L) / lum(exp*(T + D) . L)`: where the
/// surroundings cover a dim part of the sky (the horizon under a sky brighter overhead),
/// `1 - visibility` is smaller than the share of the cosine lobe they cover, though the
/// fitted depths block that part as they should. Scaled by the unweighted share, the
/// bounce off the surroundings was cut where nothing leaked: the primitives' floor took
/// 58 % of the bounce Cycles' light paths give it (`docs/method/bounce-light.md`). So the
/// gather's occlusion channel is weighted by the sky's luminance `l(w)`: it carries the
/// order-[`ORDER`] projection of `occlusion(w) l(w)`, and a receiver's covered share is
/// its cosine convolution over that of `l` alone. Under a constant sky it is the
/// unweighted share.
#[derive(Clone, Debug)]
pub struct SkyWeighting {
    /// Per node of a product quadrature, `w_i l(x_i)` and the basis at `x_i`.
    nodes: Vec<(f64, [f64; COUNT])>,
    /// `l` projected to order [`ORDER`].
    luminance: [f64; COUNT],
}

impl SkyWeighting {
    /// The weighting by a sky of luminance `luminance`, SH coefficients of the kernel's
    /// order (4 by default): its bands from [`ORDER`] on are dropped, as the gather holds
    /// nothing finer. `None` for a sky with no light, whose visibility pass is 1.
    pub fn new(luminance: &[f64]) -> Option<Self> {
        let mut projected = [0.0f64; COUNT];
        for (to, from) in projected.iter_mut().zip(luminance) {
            *to = *from;
        }
        if projected[0] <= 0.0 || projected.iter().any(|v| !v.is_finite()) {
            return None;
        }
        // Gauss-Legendre in z with twice as many azimuths: exact for the product of three
        // functions of order ORDER (degree 3 (ORDER - 1)).
        let quadrature = crate::sh::quadrature::SphereQuadrature::gauss(ORDER + 2);
        let nodes = quadrature
            .directions
            .iter()
            .zip(&quadrature.weights)
            .map(|(&d, &w)| {
                let mut y = [0.0f64; COUNT];
                eval_basis(ORDER, d, &mut y);
                let l: f64 = projected.iter().zip(&y).map(|(a, b)| a * b).sum();
                (w * l.max(0.0), y)
            })
            .collect();
        Some(Self { nodes, luminance: projected })
    }

    /// The projection of `occlusion(w) l(w)`, `occlusion` as SH.
    pub(super) fn weigh(&self, occlusion: &[f64; COUNT]) -> [f64; COUNT] {
        let mut out = [0.0f64; COUNT];
        for (weight, y) in &self.nodes {
            let value: f64 = occlusion.iter().zip(y).map(|(a, b)| a * b).sum();
            let scaled = weight * value;
            for (o, b) in out.iter_mut().zip(y) {
                *o += scaled * b;
            }
        }
        out
    }

    /// `integral l(w) max(n . w, 0) dw` at the normal whose basis is `y`, as
    /// [`convolved_with`] convolves the weighted occlusion: `pi` times the luminance
    /// under a constant sky.
    pub(super) fn open(&self, y: &[f64; COUNT]) -> f64 {
        convolved_one(&self.luminance, y, clamped_cosine_factor).max(1e-12)
    }
}

/// What the bounce gathered over a receiver's covered share `occlusion` of its cosine
/// lobe is scaled by, given the direct light's visibility of it (`visibility`, 1 where
/// nothing covers it): `(1 - visibility) / occlusion`, at most 1. The log-SH visibility
/// lets through part of the light its occluders block (their log depth is finite,
/// paper 000 Eq. 2), so the covered share it darkens, `1 - visibility`, is smaller than
/// the share the surroundings cover; scaling the bounce to it keeps a closed white
/// furnace at most 1 (`tests/extremes.rs`), where adding the whole bounce to the light
/// let through counted that share twice. The pass is weighted by the environment's
/// light, and is 1 by convention where the environment is black (a Sun lamp under a
/// black World): a visibility of 1 leaves the bounce unscaled.
pub(super) fn leak_scale(visibility: Option<f32>, occlusion: f64) -> f64 {
    match visibility {
        Some(v) if occlusion > 1e-6 && v < 1.0 => ((1.0 - f64::from(v)) / occlusion).clamp(0.0, 1.0),
        _ => 1.0,
    }
}

pub(super) fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d: [f64; 3] = std::array::from_fn(|k| a[k] - b[k]);
    dot(d, d).sqrt()
}

/// Incident radiance as SH of [`ORDER`], per [`CHANNELS`].
pub(super) type Incident = [[f64; COUNT]; CHANNELS];
/// [`Incident`] as stored at the gather's nodes.
pub(super) type Incident32 = [[f32; COUNT]; CHANNELS];

/// `sum_lm factor(l) U_lm y_lm(axis)` per channel, clamped at 0, given the basis at the
/// axis, `y`: with the clamped cosine's factors, the irradiance about `axis`.
pub(super) fn convolved_with(incident: &Incident, y: &[f64; COUNT], factor: impl Fn(usize) -> f64) -> [f64; CHANNELS] {
    std::array::from_fn(|c| convolved_one(&incident[c], y, &factor).max(0.0))
}

/// `sum_lm factor(l) U_lm y_lm` of one SH vector, unclamped.
fn convolved_one(coefficients: &[f64; COUNT], y: &[f64; COUNT], factor: impl Fn(usize) -> f64) -> f64 {
    let mut sum = 0.0;
    for l in 0..ORDER {
        let f = factor(l);
        for i in l * l..(l + 1) * (l + 1) {
            sum += f * coefficients[i] * y[i];
        }
    }
    sum
}

/// A frame's bounce light per pixel, by where it comes from.
#[derive(Clone, Debug)]
pub struct IndirectParts {
    /// From the terrain: the height field or the ground plane.
    pub heightfield: Vec<[f32; 3]>,
    pub blockers: Vec<[f32; 3]>,
}

impl IndirectParts {
    /// The sum of the two parts per pixel.
    pub fn total(&self) -> Vec<[f32; 3]> {
        self.heightfield.iter().zip(&self.blockers).map(|(h, b)| [0, 1, 2].map(|c| h[c] + b[c])).collect()
    }
}
