//! The light a point receives through its lobes: the environment's (in SH, or read from
//! a prefiltered map for a glossy lobe, [`super::super::glossy`]) and the sharp lights'
//! ([`super::super::sun`]), each shadowed by the point's visibility.

use super::*;

impl<T: Real> ShadingKernel<T> {
    /// The diffuse and glossy radiance at `point` ([`Self::environment_lit`]), without the
    /// diffuse lobe's light where the albedo is black (a metal): nothing needs it then.
    pub(super) fn environment_radiance(
        &self,
        occluders: Occluders,
        visibility: &[T],
        occlusion: &[T],
        lobes: &MaterialLobes<T>,
        point: &SurfacePoint,
    ) -> ([f32; 3], [f32; 3]) {
        match &lobes.material {
            Material::Phong { albedo: [0.0, 0.0, 0.0], specular, .. } => {
                let phong = lobes.phong.as_ref().expect("phong materials carry their lobe");
                ([0.0; 3], self.glossy_lit(occluders, visibility, occlusion, phong, lobes, point, *specular))
            }
            _ => {
                let (_, diffuse, glossy) = self.environment_lit(occluders, visibility, occlusion, lobes, point);
                (diffuse, glossy)
            }
        }
    }

    /// The environment's light through the diffuse lobe, and the diffuse and glossy
    /// radiance at `point`, each times the material's albedo or specular colour.
    pub(crate) fn environment_lit(
        &self,
        occluders: Occluders,
        visibility: &[T],
        occlusion: &[T],
        lobes: &MaterialLobes<T>,
        point: &SurfacePoint,
    ) -> ([T; 3], [f32; 3], [f32; 3]) {
        let n = point.normal;
        let lit_diffuse = self.lit(visibility, &self.diffuse, n);
        let diffuse_light = self.less_hidden_detail(self.open_corrected(lit_diffuse, n), occluders, point);
        let scale = |c: [T; 3], k: [f32; 3]| [0, 1, 2].map(|i| c[i].to_f32().unwrap_or(0.0) * k[i]);
        match &lobes.material {
            Material::Diffuse { albedo } | Material::Heightfield { albedo } => {
                (lit_diffuse, scale(diffuse_light, *albedo), [0.0; 3])
            }
            Material::Phong { albedo, specular, .. } => {
                let diffuse = scale(diffuse_light, *albedo);
                let phong = lobes.phong.as_ref().expect("phong materials carry their lobe");
                let glossy = self.glossy_lit(occluders, visibility, occlusion, phong, lobes, point, *specular);
                (lit_diffuse, diffuse, glossy)
            }
            Material::Water { .. } => ([T::zero(); 3], [0.0; 3], [0.0; 3]),
        }
    }

    /// The environment's diffuse light at a receiver of normal `n` whose log-SH light is
    /// `lit = exp*(V + D) . L`: the open receiver's light in full, `E(n) / pi` from the
    /// order-8 projection of the map ([`OpenIrradiance`]), times log-SH's share of it,
    /// `lit / exp*(T + D) . L` per channel in `[0, 1]`; `lit` itself without a map or
    /// where the open receiver gets no light.
    pub(crate) fn open_corrected(&self, lit: [T; 3], n: [f64; 3]) -> [T; 3] {
        let Some(irradiance) = &self.irradiance else { return lit };
        let open = open_lit(self.order, &self.diffuse_open, n, &self.light);
        let full = irradiance.at(n);
        [0, 1, 2].map(|c| {
            let lit = lit[c].to_f64().unwrap_or(0.0);
            T::of(open_corrected_channel(lit, open[c].to_f64().unwrap_or(0.0), full[c]))
        })
    }

    /// `light`, the diffuse light at `point`, less the detail its blockers' caps hide
    /// ([`Self::hidden_detail`], its cosine-weighted integral divided by pi), at least 0.
    fn less_hidden_detail(&self, light: [T; 3], occluders: Occluders, point: &SurfacePoint) -> [T; 3] {
        if self.cap_detail.is_none() {
            return light;
        }
        let detail = self.hidden_detail(occluders, point);
        [0, 1, 2].map(|c| T::of((light[c].to_f64().unwrap_or(0.0) - detail[c] / std::f64::consts::PI).max(0.0)))
    }

    /// The glossy radiance of a Phong material at `point`, times its specular colour: the
    /// prefiltered term, or the Phong lobe in log-SH with `--glossy sh`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn glossy_lit(
        &self,
        occluders: Occluders,
        visibility: &[T],
        occlusion: &[T],
        phong: &LobeTable<T>,
        lobes: &MaterialLobes<T>,
        point: &SurfacePoint,
        specular: [f32; 3],
    ) -> [f32; 3] {
        let reflected = reflect_view(point.view_origin, point.position, point.normal);
        match &lobes.sharp {
            Some(sharp) => {
                let g = self.prefiltered_glossy(occluders, occlusion, phong, sharp, point, reflected);
                [0, 1, 2].map(|i| (g[i] * f64::from(specular[i])) as f32)
            }
            None => {
                let c = self.lit(visibility, phong, reflected);
                [0, 1, 2].map(|i| c[i].to_f32().unwrap_or(0.0) * specular[i])
            }
        }
    }

    /// `A(n . v) P(R) O` ([`super::glossy`]): the prefiltered light along the mirror
    /// direction, times the lobe's albedo, times the specular occlusion: the cone test of
    /// the lobe's core, log-SH's `lum(exp*(V + lobe) . L) / lum(exp*(lobe) . L)` (1 where
    /// the open lobe gets no light), or a blend of the two, in `[0, 1]`.
    pub(super) fn prefiltered_glossy(
        &self,
        occluders: Occluders,
        occlusion: &[T],
        phong: &LobeTable<T>,
        sharp: &SharpGlossy<T>,
        point: &SurfacePoint,
        reflected: [f64; 3],
    ) -> [f64; 3] {
        let (cone, sh_weight) = self.prefiltered_weights(occluders, sharp, point, reflected);
        let by_sh = if sh_weight > 0.0 {
            let shadowed = self.lit(occlusion, phong, reflected);
            let open = open_lit(self.order, &sharp.open, reflected, &self.light);
            occlusion_ratio(shadowed, open)
        } else {
            0.0
        };
        let weight = cone + sh_weight * by_sh;
        sharp.prefiltered.lookup(reflected).map(|c| f64::from(c) * weight)
    }

    /// The two light-independent factors of the prefiltered glossy term's weight
    /// `A(n . v) O`: `A share cone` and `A (1 - share)`, the second to be multiplied by
    /// log-SH's occlusion ratio ([`occlusion_ratio`]).
    pub(crate) fn prefiltered_weights(
        &self,
        occluders: Occluders,
        sharp: &SharpGlossy<T>,
        point: &SurfacePoint,
        reflected: [f64; 3],
    ) -> (f64, f64) {
        let share = sharp.cone_share;
        let by_cone = if share > 0.0 {
            let core = DiskDirections::of_shape(reflected, &sharp.core);
            let planes = Planes { tangent: false, ground: None };
            let visible = core.visibility(
                occluders.blockers,
                occluders.horizons,
                planes,
                point.position,
                point.normal,
                point.object,
            );
            visible.iter().zip(&sharp.cone_weights).map(|(v, w)| v * w).sum::<f64>()
        } else {
            0.0
        };
        // n . v = n . R, R the view mirrored about n.
        let n_dot_r = dot(reflected, point.normal);
        let divisor = below_tangent_divisor(&sharp.share_above, n_dot_r, point.normal[2], self.sky_only);
        let albedo = albedo_lookup(&sharp.albedo, n_dot_r) / divisor;
        (albedo * share * by_cone, albedo * (1.0 - share))
    }

    /// The height field's horizon along each sun from each of `points` (a row's), marched
    /// eight receivers at a time ([`HorizonPyramid::horizons_against`]: each the same bits
    /// as marched alone), as [`Self::shade_lobes_known`] reads them: `known[i * suns + k]`
    /// for point `i` and sun `k`. Empty without a height field or suns.
    pub fn suns_along_row(&self, horizons: Option<&HorizonPyramid>, points: &[SurfacePoint]) -> Vec<KnownAlongSun> {
        let Some(pyramid) = horizons.filter(|_| !self.suns.is_empty()) else {
            return Vec::new();
        };
        let count = self.suns.len();
        let mut known = vec![KnownAlongSun { horizon: None, blockers: true }; points.len() * count];
        let positions: Vec<[f64; 3]> = points.iter().map(|p| p.position).collect();
        let mut against = vec![HorizonAgainst::Below; points.len()];
        for (k, sun) in self.suns.iter().enumerate() {
            let Some(along) = sun.disk.march_band() else { continue };
            pyramid.horizons_against(&positions, along.azimuth, along.horizontal_reach, along.band, &mut against);
            for (i, horizon) in against.iter().enumerate() {
                known[i * count + k].horizon = Some(*horizon);
            }
        }
        known
    }

    /// The sharp lights' diffuse and specular radiance at `point` ([`super::sun`]), each
    /// times the material's albedo or specular colour: of `suns` (the kernel's, or some of
    /// them), and of every point lamp where `lamps`; and the share of `suns` alone in it
    /// (the sums before the point lamps are added: the same bits as without lamps). Sun
    /// `k`'s horizon is `known[k]`'s where given, marched here otherwise.
    pub(crate) fn sharp_lit(
        &self,
        occluders: Occluders,
        point: &SurfacePoint,
        material: &Material,
        suns: &[SunDisk],
        lamps: bool,
        known: Option<&[KnownAlongSun]>,
    ) -> (SharpLit, SharpLit) {
        let (mut diffuse, mut glossy) = ([0.0f64; 3], [0.0f64; 3]);
        let dark = ([0.0; 3], [0.0; 3]);
        let (albedo, phong) = match material {
            Material::Diffuse { albedo } | Material::Heightfield { albedo } => (*albedo, None),
            Material::Phong { albedo, specular, exponent } => (*albedo, Some((*specular, *exponent))),
            Material::Water { .. } => return (dark, dark),
        };
        let as_f32 = |d: [f64; 3], g: [f64; 3]| (d.map(|c| c as f32), g.map(|c| c as f32));
        let n = point.normal;
        // The glossy lobe: GGX's BRDF, scaled by the lamps' table
        // ([`super::super::glossy::lamp_scale_table`]); with `--glossy phong` the Phong lobe
        // about the mirrored view, scaled so too; with `--glossy sh` Eq. 27's Phong lobe. The
        // mirrored view, which a diffuse material does not read (a square root and three
        // divisions a pixel, 3 % of a turn of the Sun-lamp scene's lamps).
        let glossy_axis = phong.map(|_| reflect_view(point.view_origin, point.position, n));
        let sharp = phong.and_then(|_| self.materials.get(&point.material)?.sharp.as_ref());
        // The view direction, mirrored back from the lobe's axis, for GGX's BRDF.
        let view = glossy_axis.map(|axis| {
            let twice = 2.0 * dot(axis, n);
            [twice * n[0] - axis[0], twice * n[1] - axis[1], twice * n[2] - axis[2]]
        });
        let lamp_scale = sharp.zip(glossy_axis).map(|(sharp, axis)| albedo_lookup(&sharp.lamp_scale, dot(axis, n)));
        // Disk `k`'s diffuse and glossy radiance, `None` where it is wholly hidden (every
        // term is then 0, the lobes being finite: the same bits as adding them). The disks
        // are lent, not moved: a disk is 1.7 KB, and moving the suns through an iterator
        // of owned and lent disks copied each twice per pixel.
        let reflected = |k: usize, sun: &SunDisk| {
            // The suns' horizons marched already with the frame's other pixels, where given,
            // and the blockers left out where none can reach the disk.
            let known = known.and_then(|known| known.get(k));
            let horizon = match (known.and_then(|known| known.horizon), occluders.horizons) {
                (Some(against), _) => DiskHorizon::Known(against),
                (None, Some(pyramid)) => DiskHorizon::Marched(pyramid),
                (None, None) => DiskHorizon::None,
            };
            // A sun's shadow map, where the frame has one, in place of the spheres.
            let map = occluders.sun_shadows.filter(|_| k < suns.len()).and_then(|maps| maps.of_sun(sun.disk.axis));
            let casters = match map {
                Some(map) => Casters::Map(map),
                None => Casters::from(occluders.blockers.filter(|_| known.is_none_or(|known| known.blockers))),
            };
            let seen = sun.seen(casters, horizon, self.ground, point.position, n, point.object);
            if seen.is_dark() {
                return None;
            }
            let d = sun.diffuse_reflected(&seen, n);
            // The lobe widened by the disk's patch ([`SharpLobe::widened`]).
            let g = phong.zip(glossy_axis).map(|((_, exponent), axis)| match (sharp, lamp_scale, view) {
                (Some(sharp), Some(a), Some(v)) => match sharp.lobe.widened(sun.disk.patch) {
                    // GGX's BRDF itself ([`GgxLit`]); the split sum's lobe about `R` is
                    // for the environment's prefiltered map alone.
                    SharpLobe::Ggx { alpha } => {
                        let (n_v, n_axis) = (dot(v, n), dot(n, sun.disk.axis));
                        let brdf = GgxLit::new(alpha, sharp.lamp_fresnel, n_v);
                        let smooth = smooth_over_disk(alpha, n_v, 1.0 - sun.disk.half_angle.cos(), n_axis);
                        sun.reflected_between_seen(&seen, |n_w, v_w| a * brdf.value(n_w, v_w), smooth, n, v)
                    }
                    lobe => sun.reflected_seen(&seen, |z| a * lobe.value(z), axis),
                },
                _ => {
                    let lobe = SharpLobe::Phong { exponent: f64::from(exponent) }.widened(sun.disk.patch);
                    sun.reflected_seen(&seen, |z| lobe.value(z), axis)
                }
            });
            Some((d, g))
        };
        let add = |diffuse: &mut [f64; 3], glossy: &mut [f64; 3], (d, g): ([f64; 3], Option<[f64; 3]>)| {
            for i in 0..3 {
                diffuse[i] += d[i] * f64::from(albedo[i]);
            }
            if let (Some(g), Some((specular, _))) = (g, phong) {
                for i in 0..3 {
                    glossy[i] += g[i] * f64::from(specular[i]);
                }
            }
        };
        for (k, sun) in suns.iter().enumerate() {
            if let Some(lit) = reflected(k, sun) {
                add(&mut diffuse, &mut glossy, lit);
            }
        }
        let suns_alone = as_f32(diffuse, glossy);
        for (j, lamp) in self.points.iter().enumerate().filter(|_| lamps) {
            if let Some(lit) = reflected(suns.len() + j, &SunDisk::of_lamp(lamp, point.position, n)) {
                add(&mut diffuse, &mut glossy, lit);
            }
        }
        (as_f32(diffuse, glossy), suns_alone)
    }
}

/// One colour channel of [`ShadingKernel::open_corrected`], which a relight shares:
/// `full * clamp(lit / open, 0, 1)`, `full` the open receiver's light from the map's
/// irradiance and `open` its log-SH light; `lit` itself where `open` is dark.
pub(crate) fn open_corrected_channel(lit: f64, open: f64, full: f64) -> f64 {
    if open > OPEN_LIGHT_FLOOR {
        full.max(0.0) * (lit / open).clamp(0.0, 1.0)
    } else {
        lit
    }
}
