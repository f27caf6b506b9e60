//! The transfer layers of a frame in memory, their EXR channels and header, and reading
//! them back (the table in the [module doc](super)).

mod read;

use super::lobe_code;
use crate::scene::output::{OutputChannel, SampleType};
use crate::scene::{LightSource, SceneError};
use crate::sh::{coefficient_count, MAX_ORDER, MIN_ORDER};
use crate::shade::bounce::IndirectParts;
use crate::shade::glossy::SharpLobe;
use crate::shade::kernel::{GlossyTransfer, PointTransfer};
use crate::shade::Tint;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The name of the header attribute that holds [`TransferHeader`] as JSON.
pub const TRANSFER_ATTRIBUTE: &str = "logshTransfer";

/// The version of the header and layers this logsh writes and reads.
pub const TRANSFER_VERSION: u32 = 1;

/// The SH convention of the transfer vectors, spelled out for readers of the file
/// ([`crate::sh::basis`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShConvention {
    pub order: usize,
    pub basis: String,
    pub index: String,
    pub normalisation: String,
    pub axes: String,
}

impl ShConvention {
    pub fn of_order(order: usize) -> Self {
        Self {
            order,
            basis: "real spherical harmonics, no Condon-Shortley phase: y_l^m = sqrt(2) K_l^m P_l^m(cos theta) \
                    cos(m phi) for m > 0, K_l^0 P_l(cos theta) for m = 0, sqrt(2) K_l^|m| P_l^|m|(cos theta) \
                    sin(|m| phi) for m < 0"
                .into(),
            index: "coefficient k = l (l + 1) + m, bands l = 0..order".into(),
            normalisation: "orthonormal over the sphere: f_k = integral of f y_k, the constant 1 is \
                            [2 sqrt(pi), 0, ...], the integral of a product is the dot product"
                .into(),
            axes: "world space of the Blender scene: right-handed, Z up; theta from +Z, phi from +X towards +Y".into(),
        }
    }
}

/// A prefiltered glossy lobe of the frame (`glossy_lobe = 3 + j` for the `j`-th).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrefilteredLobe {
    /// The material it belongs to.
    pub material: u32,
    pub lobe: SharpLobe,
    /// `exp*(Phong lobe)` about +Z as ZH (`order` values): the specular occlusion's
    /// unoccluded denominator.
    pub open: Vec<f64>,
}

/// What a transfer file's header records (module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransferHeader {
    pub version: u32,
    /// The scene directory and frame number the frame was rendered from.
    pub scene: std::path::PathBuf,
    pub frame: i64,
    pub sh: ShConvention,
    /// The light the frame was rendered with.
    pub light: LightSource,
    /// `--light-window`, applied to the light's projection.
    pub light_window: String,
    /// The ground plane hides the map's lower hemisphere from the prefiltered glossy term.
    pub sky_only: bool,
    /// The frame has a height field, sphere blockers (which visibility passes are not 1).
    pub heightfield: bool,
    pub blockers: bool,
    pub lobes: Vec<PrefilteredLobe>,
    /// The scene's Sun lamps as rendered (after `render --light-rotation`, which turns
    /// them with the map), azimuth and elevation in degrees. Their light and sharp
    /// shadows are in the `lamps_*` layers; a relight that turns the map turns them too,
    /// checked against this record ([`super::SunLampTurn`]). Empty in files written
    /// before this was recorded.
    #[serde(default)]
    pub sun_lamps: Vec<[f64; 2]>,
    /// The render's `--light-rotation` in degrees, whatever the light (a constant light's
    /// turn turns only the Sun lamps): the turn a relight starts the scene's Sun lamps
    /// from.
    #[serde(default)]
    pub light_turn: f64,
    /// The render's shading settings, with which a relight that turns the map shades the
    /// Sun lamps again ([`super::SunLampTurn`]). `None` in files written before they were
    /// recorded.
    #[serde(default)]
    pub settings: Option<crate::shade::ShadingSettings>,
    /// What the frame's Sun lamps were shaded from, which a relight that turns them
    /// checks the scene against ([`super::SunLampInputs`]). `None` in frames without a
    /// Sun lamp and in files written before it was recorded (there only the lamps'
    /// directions are checked).
    #[serde(default)]
    pub sun_lamp_inputs: Option<super::SunLampInputs>,
    /// The scene's colour management for previews, its LUT file absolute
    /// ([`crate::scene::view`]).
    pub view: Option<crate::scene::ViewSpec>,
    /// A CRC-32 of the environment map's file as rendered: a relight that reads the map
    /// again from `light` checks it is the one the frame was lit with
    /// ([`super::RelightOptions::check_rendered_map`]). `None` without a map, and in files
    /// written before it was recorded.
    #[serde(default)]
    pub light_file_crc: Option<u32>,
    /// How many sectors of azimuths the `horizon` layer keeps per pixel
    /// ([`crate::heightfield::HorizonPyramid::horizon_sectors`]) where the frame holds it;
    /// `None` without the layer, and in files written before the count was recorded
    /// (`UNRECORDED_SECTORS`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub horizon_sectors: Option<usize>,
    /// The open receiver's diffuse ZH about +Z, `exp*(T + D)` (`order` values), where the
    /// render corrected the diffuse light to its map's irradiance
    /// ([`crate::shade::kernel::open_corrected_channel`]); the frame then holds the
    /// `diffuse_normal` layer it was corrected at. Empty without a map, and in files
    /// written before the correction.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub open_diffuse: Vec<f64>,
}

/// The sectors the `horizon` layer kept before its header recorded them: quarters, then
/// eighths of the W azimuths (or W where fewer), known by how many channels it holds.
pub const UNRECORDED_SECTORS: [usize; 2] = [4, 8];

/// Most prefiltered lobes a frame may list (one per Phong material).
pub const MAX_LOBES: usize = 1024;

/// Most Sun lamps a frame's header may list (a scene's own limit on its lamps,
/// [`crate::scene::MAX_SUNS`]).
pub const MAX_SUN_LAMPS: usize = crate::scene::MAX_SUNS;

impl TransferHeader {
    /// Refuses a header a relight cannot use, naming `file`: an order outside the
    /// supported range, a light or lobe that is not finite or out of range.
    fn check(&self, file: &Path) -> Result<(), SceneError> {
        let order = self.sh.order;
        let bad = |what: String| Err(SceneError::invalid(file, format!("its {TRANSFER_ATTRIBUTE} header: {what}")));
        if self.version != TRANSFER_VERSION {
            return bad(format!(
                "version {} is not {TRANSFER_VERSION}, the one this logsh reads: relight it with the logsh that rendered it",
                self.version
            ));
        }
        if !(MIN_ORDER..=MAX_ORDER).contains(&order) {
            return bad(format!("transfer order {order} is not in {MIN_ORDER}..={MAX_ORDER}"));
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match &self.light {
            LightSource::Environment { strength, rotation, turn, .. } => {
                if !(strength.is_finite() && *strength >= 0.0 && finite(rotation) && turn.is_finite()) {
                    return bad("the environment's strength or rotation is not a finite value".into());
                }
            }
            LightSource::Constant(c) => {
                if !c.iter().all(|v| v.is_finite() && *v >= 0.0) {
                    return bad("the constant light is not finite and >= 0".into());
                }
            }
            LightSource::Sh(v) => {
                let n = (v.len() as f64).sqrt().round() as usize;
                if n * n != v.len()
                    || !(1..=crate::scene::light::MAX_SH_LIGHT_ORDER).contains(&n)
                    || !v.iter().all(|c| finite(c))
                {
                    return bad(format!(
                        "the SH light has {} coefficients; give n^2 finite ones, n from 1 to {}",
                        v.len(),
                        crate::scene::light::MAX_SH_LIGHT_ORDER
                    ));
                }
            }
        }
        if self.sun_lamps.len() > MAX_SUN_LAMPS
            || !self.sun_lamps.iter().all(|lamp| finite(lamp))
            || !self.light_turn.is_finite()
        {
            return bad(format!(
                "its Sun lamps: give at most {MAX_SUN_LAMPS}, each a finite azimuth and elevation, and a finite light_turn"
            ));
        }
        if self.lobes.len() > MAX_LOBES {
            return bad(format!("{} prefiltered lobes, more than {MAX_LOBES}", self.lobes.len()));
        }
        for lobe in &self.lobes {
            let width = match lobe.lobe {
                SharpLobe::Ggx { alpha } => alpha > 0.0 && alpha <= 1.0,
                SharpLobe::Phong { exponent } => exponent.is_finite() && exponent > 0.0,
            };
            if !width || lobe.open.len() != order || !finite(&lobe.open) {
                return bad(format!("the lobe of material {} is not a finite lobe of order {order}", lobe.material));
            }
        }
        if !(self.open_diffuse.is_empty() || self.open_diffuse.len() == order && finite(&self.open_diffuse)) {
            return bad(format!("open_diffuse is not {order} finite values"));
        }
        Ok(())
    }
}

/// Whether an EXR whose headers are `meta` records transfer layers.
pub fn holds_transfer(meta: &exr::meta::MetaData) -> bool {
    meta.headers.iter().any(|h| h.own_attributes.other.keys().any(|k| k.as_slice() == TRANSFER_ATTRIBUTE.as_bytes()))
}

/// The checked [`TransferHeader`] of `file`, whose EXR headers are `meta`.
fn header_of(file: &Path, meta: &exr::meta::MetaData) -> Result<TransferHeader, SceneError> {
    let text = meta.headers.iter().find_map(|h| {
        h.own_attributes
            .other
            .iter()
            .find(|(k, _)| k.as_slice() == TRANSFER_ATTRIBUTE.as_bytes())
            .map(|(_, v)| v.clone())
    });
    let header: TransferHeader = match text {
        Some(exr::meta::attribute::AttributeValue::Text(t)) => serde_json::from_str(&t.to_string())
            .map_err(|e| SceneError::invalid(file, format!("its {TRANSFER_ATTRIBUTE} header does not read: {e}")))?,
        _ => {
            // A relight's own output (beside its light.json) holds passes, not transfer.
            let relit = file.with_extension("light.json").is_file();
            let hint = if relit {
                "; it is a relit frame (beside its light.json), and a relight writes no transfer layers: relight the \
                 frame it was relit from"
            } else {
                ""
            };
            return Err(SceneError::invalid(
                file,
                format!(
                    "has no transfer layers (no logshTransfer header): render it with `logsh render --transfer`{hint}"
                ),
            ));
        }
    };
    header.check(file)?;
    Ok(header)
}

/// The transfer layers of one frame, row-major from the top row; the SH layers hold
/// `count` coefficients per pixel.
#[derive(Clone, Debug)]
pub struct TransferFrame {
    pub width: usize,
    pub height: usize,
    pub header: TransferHeader,
    pub diffuse: Vec<f32>,
    pub unoccluded: Vec<f32>,
    /// Present in frames with both a height field and blockers.
    pub heightfield: Option<Vec<f32>>,
    pub blockers: Option<Vec<f32>>,
    /// Present in scenes with a Phong material.
    pub specular: Option<Vec<f32>>,
    pub albedo: Vec<[f32; 3]>,
    pub specular_colour: Vec<[f32; 3]>,
    pub lamps_diffuse: Vec<[f32; 3]>,
    pub lamps_specular: Vec<[f32; 3]>,
    /// The Sun lamps' part of `lamps_*`, where the header lists Sun lamps: what a relight
    /// that turns them takes out ([`super::SunLampTurn`]).
    pub sun_lamps_diffuse: Option<Vec<[f32; 3]>>,
    pub sun_lamps_specular: Option<Vec<[f32; 3]>>,
    pub glossy_lobe: Vec<f32>,
    pub glossy_direction: Vec<[f32; 3]>,
    pub glossy_weight: Vec<[f32; 2]>,
    /// 1 where a surface was shaded, 0 on the background (the beauty's alpha).
    pub alpha: Vec<f32>,
    /// Per pixel, the height field's highest horizon tangent in each sector of the W
    /// azimuths of the render's settings
    /// ([`HorizonPyramid::sector_maxima`](crate::heightfield::HorizonPyramid::sector_maxima),
    /// as half floats at least those marched; infinite where none was), in frames whose Sun
    /// lamps a height field may shadow: what bounds the turned lamps' horizons
    /// ([`super::SunLampTurn`]). `None` in other frames and in files written before it was
    /// kept.
    pub horizons: Option<Vec<f32>>,
    /// Per pixel, the normal at which the diffuse light was corrected to the map's
    /// irradiance (the surface's, or the reflected surface's under water), where the
    /// header holds `open_diffuse`.
    pub diffuse_normal: Option<Vec<[f32; 3]>>,
    /// The render's bounce light from the terrain and from the blockers
    /// (`indirect_heightfield`, `indirect_blockers`), which a relight keeps as rendered;
    /// `None` in a frame written before bounce light, or while one is being shaded.
    pub bounce: Option<IndirectParts>,
    /// The G-buffer's world position and normal (`P`, `N`), passed through (shared with
    /// the passes relit from it).
    pub position: std::sync::Arc<[[f32; 3]]>,
    pub normal: std::sync::Arc<[[f32; 3]]>,
}

/// What one pixel's transfer is, beyond a surface point's: how it reads the light
/// directly (background, water mirroring the sky) and its tint.
pub enum PixelTransfer<'a> {
    /// The background: the light along the camera ray (`None`: black).
    Background { ray: Option<[f64; 3]> },
    /// Water mirroring the sky along `mirror`, and the scene's Sun lamps there.
    Mirror { tint: [f32; 3], mirror: [f64; 3], suns: [f32; 3] },
    /// Water mirroring a lamp.
    Lamp { tint: [f32; 3], radiance: [f32; 3] },
    /// A surface point, its diffuse parts times `tint.diffuse` and its specular parts
    /// times `tint.specular`.
    Surface { point: &'a PointTransfer, tint: Tint },
}

/// One row of a frame's layers ([`TransferFrame::rows_mut`]), its pixels to be written
/// with [`set`](Self::set).
pub struct TransferRow<'a> {
    count: usize,
    diffuse: &'a mut [f32],
    unoccluded: &'a mut [f32],
    heightfield: Option<&'a mut [f32]>,
    blockers: Option<&'a mut [f32]>,
    specular: Option<&'a mut [f32]>,
    albedo: &'a mut [[f32; 3]],
    specular_colour: &'a mut [[f32; 3]],
    lamps_diffuse: &'a mut [[f32; 3]],
    lamps_specular: &'a mut [[f32; 3]],
    sun_lamps_diffuse: Option<&'a mut [[f32; 3]]>,
    sun_lamps_specular: Option<&'a mut [[f32; 3]]>,
    glossy_lobe: &'a mut [f32],
    glossy_direction: &'a mut [[f32; 3]],
    glossy_weight: &'a mut [[f32; 2]],
    alpha: &'a mut [f32],
    /// One value per sector and pixel.
    horizons: Option<&'a mut [f32]>,
    diffuse_normal: Option<&'a mut [[f32; 3]]>,
}

impl TransferRow<'_> {
    /// Writes pixel `x` of the row; `lobes` from [`TransferFrame::lobe_indices`].
    pub fn set(&mut self, x: usize, pixel: PixelTransfer, lobes: &BTreeMap<u32, usize>) {
        let count = self.count;
        let dark = PointTransfer::DARK;
        let tinted = |tint: [f32; 3], c: [f32; 3]| [0, 1, 2].map(|k| tint[k] * c[k]);
        let to_f32 = |d: [f64; 3]| d.map(|c| c as f32);
        // The Sun lamps' part of the specular lamps: all of a water mirror's.
        let (point, tint, alpha, lobe, direction, lamps_specular, sun_lamps_specular, colour) = match pixel {
            PixelTransfer::Background { ray } => {
                let lobe = if ray.is_some() { lobe_code::MIRROR } else { lobe_code::NONE };
                (&dark, [1.0; 3], 0.0, lobe, ray.map_or([0.0; 3], to_f32), [0.0; 3], [0.0; 3], [1.0; 3])
            }
            PixelTransfer::Mirror { tint, mirror, suns } => {
                let suns = tinted(tint, suns);
                (&dark, tint, 1.0, lobe_code::MIRROR, to_f32(mirror), suns, suns, tint)
            }
            PixelTransfer::Lamp { tint, radiance } => {
                (&dark, tint, 1.0, lobe_code::NONE, [0.0; 3], tinted(tint, radiance), [0.0; 3], [0.0; 3])
            }
            PixelTransfer::Surface { point, tint } => {
                let (lobe, direction) = match point.glossy {
                    GlossyTransfer::None => (lobe_code::NONE, [0.0; 3]),
                    GlossyTransfer::Sh => (lobe_code::SH, [0.0; 3]),
                    GlossyTransfer::Prefiltered { material, direction, .. } => {
                        (lobe_code::PREFILTERED + lobes[&material] as f32, to_f32(direction))
                    }
                };
                let specular = tint.specular;
                (
                    point,
                    tint.diffuse,
                    1.0,
                    lobe,
                    direction,
                    tinted(specular, point.lamps_specular),
                    tinted(specular, point.sun_lamps_specular),
                    tinted(specular, point.specular_colour),
                )
            }
        };
        let at = x * count..(x + 1) * count;
        self.diffuse[at.clone()].copy_from_slice(&point.diffuse[..count]);
        self.unoccluded[at.clone()].copy_from_slice(&point.unoccluded[..count]);
        for (layer, values) in [
            (&mut self.heightfield, &point.heightfield),
            (&mut self.blockers, &point.blockers),
            (&mut self.specular, &point.specular),
        ] {
            if let Some(layer) = layer {
                layer[at.clone()].copy_from_slice(&values[..count]);
            }
        }
        self.albedo[x] = tinted(tint, point.albedo);
        self.specular_colour[x] = colour;
        self.lamps_diffuse[x] = tinted(tint, point.lamps_diffuse);
        self.lamps_specular[x] = lamps_specular;
        if let Some(layer) = &mut self.sun_lamps_diffuse {
            layer[x] = tinted(tint, point.sun_lamps_diffuse);
        }
        if let Some(layer) = &mut self.sun_lamps_specular {
            layer[x] = sun_lamps_specular;
        }
        self.glossy_lobe[x] = lobe;
        self.glossy_direction[x] = direction;
        self.glossy_weight[x] = match point.glossy {
            GlossyTransfer::Prefiltered { cone, sh_weight, .. } => [cone as f32, sh_weight as f32],
            _ => [0.0; 2],
        };
        self.alpha[x] = alpha;
        if let Some(layer) = &mut self.horizons {
            let sectors = layer.len() / self.alpha.len();
            for (kept, &tangent) in layer[x * sectors..(x + 1) * sectors].iter_mut().zip(&point.horizons) {
                *kept = half_at_least(tangent);
            }
        }
        if let Some(layer) = &mut self.diffuse_normal {
            layer[x] = point.normal;
        }
    }
}

impl TransferFrame {
    /// A frame of `width` x `height` with the optional layers the frame has, every value
    /// zero (the horizons infinite, `horizon_sectors` per pixel where not 0, which its
    /// header records), to write pixels into row by row ([`rows_mut`](Self::rows_mut)).
    pub fn new(
        width: usize,
        height: usize,
        header: TransferHeader,
        heightfield_and_blockers: bool,
        phong: bool,
        horizon_sectors: usize,
    ) -> Self {
        let n = width * height;
        let coefficients = n * coefficient_count(header.sh.order);
        let layer = |present: bool| present.then(|| vec![0.0; coefficients]);
        let sun_lamps = !header.sun_lamps.is_empty();
        let corrected = !header.open_diffuse.is_empty();
        Self {
            width,
            height,
            header: TransferHeader { horizon_sectors: (horizon_sectors > 0).then_some(horizon_sectors), ..header },
            diffuse: vec![0.0; coefficients],
            unoccluded: vec![0.0; coefficients],
            heightfield: layer(heightfield_and_blockers),
            blockers: layer(heightfield_and_blockers),
            specular: layer(phong),
            albedo: vec![[0.0; 3]; n],
            specular_colour: vec![[0.0; 3]; n],
            lamps_diffuse: vec![[0.0; 3]; n],
            lamps_specular: vec![[0.0; 3]; n],
            sun_lamps_diffuse: sun_lamps.then(|| vec![[0.0; 3]; n]),
            sun_lamps_specular: sun_lamps.then(|| vec![[0.0; 3]; n]),
            glossy_lobe: vec![0.0; n],
            glossy_direction: vec![[0.0; 3]; n],
            glossy_weight: vec![[0.0; 2]; n],
            alpha: vec![0.0; n],
            horizons: (horizon_sectors > 0).then(|| vec![f32::INFINITY; n * horizon_sectors]),
            diffuse_normal: corrected.then(|| vec![[0.0; 3]; n]),
            bounce: None,
            position: std::sync::Arc::from([]),
            normal: std::sync::Arc::from([]),
        }
    }

    pub fn order(&self) -> usize {
        self.header.sh.order
    }

    pub fn count(&self) -> usize {
        coefficient_count(self.order())
    }

    /// The index of each prefiltered lobe's material in [`TransferHeader::lobes`].
    pub fn lobe_indices(&self) -> BTreeMap<u32, usize> {
        self.header.lobes.iter().enumerate().map(|(j, lobe)| (lobe.material, j)).collect()
    }

    /// How many sectors of azimuths the `horizon` layer keeps per pixel, 0 without it.
    pub fn horizon_sectors(&self) -> usize {
        self.horizons.as_ref().map_or(0, |layer| layer.len() / (self.width * self.height).max(1))
    }

    /// The frame's rows, each to write its pixels into (in parallel).
    pub fn rows_mut(&mut self) -> Vec<TransferRow<'_>> {
        let (width, count, sectors) = (self.width.max(1), self.count(), self.horizon_sectors());
        let sh = width * count;
        let (mut diffuse, mut unoccluded) = (self.diffuse.chunks_mut(sh), self.unoccluded.chunks_mut(sh));
        let mut heightfield = self.heightfield.as_deref_mut().map(|layer| layer.chunks_mut(sh));
        let mut blockers = self.blockers.as_deref_mut().map(|layer| layer.chunks_mut(sh));
        let mut specular = self.specular.as_deref_mut().map(|layer| layer.chunks_mut(sh));
        let mut albedo = self.albedo.chunks_mut(width);
        let mut specular_colour = self.specular_colour.chunks_mut(width);
        let mut lamps_diffuse = self.lamps_diffuse.chunks_mut(width);
        let mut lamps_specular = self.lamps_specular.chunks_mut(width);
        let mut sun_lamps_diffuse = self.sun_lamps_diffuse.as_deref_mut().map(|layer| layer.chunks_mut(width));
        let mut sun_lamps_specular = self.sun_lamps_specular.as_deref_mut().map(|layer| layer.chunks_mut(width));
        let mut glossy_lobe = self.glossy_lobe.chunks_mut(width);
        let mut glossy_direction = self.glossy_direction.chunks_mut(width);
        let mut glossy_weight = self.glossy_weight.chunks_mut(width);
        let mut alpha = self.alpha.chunks_mut(width);
        let mut horizons = self.horizons.as_deref_mut().map(|layer| layer.chunks_mut((width * sectors).max(1)));
        let mut diffuse_normal = self.diffuse_normal.as_deref_mut().map(|layer| layer.chunks_mut(width));
        let row = "every layer has a row per row of the frame";
        (0..self.height)
            .map(|_| TransferRow {
                count,
                diffuse: diffuse.next().expect(row),
                unoccluded: unoccluded.next().expect(row),
                heightfield: heightfield.as_mut().map(|rows| rows.next().expect(row)),
                blockers: blockers.as_mut().map(|rows| rows.next().expect(row)),
                specular: specular.as_mut().map(|rows| rows.next().expect(row)),
                albedo: albedo.next().expect(row),
                specular_colour: specular_colour.next().expect(row),
                lamps_diffuse: lamps_diffuse.next().expect(row),
                lamps_specular: lamps_specular.next().expect(row),
                sun_lamps_diffuse: sun_lamps_diffuse.as_mut().map(|rows| rows.next().expect(row)),
                sun_lamps_specular: sun_lamps_specular.as_mut().map(|rows| rows.next().expect(row)),
                glossy_lobe: glossy_lobe.next().expect(row),
                glossy_direction: glossy_direction.next().expect(row),
                glossy_weight: glossy_weight.next().expect(row),
                alpha: alpha.next().expect(row),
                horizons: horizons.as_mut().map(|rows| rows.next().expect(row)),
                diffuse_normal: diffuse_normal.as_mut().map(|rows| rows.next().expect(row)),
            })
            .collect()
    }

    /// The SH layers present, by name.
    pub fn sh_layers(&self) -> Vec<(&'static str, &[f32])> {
        let mut layers = vec![("sh_diffuse", self.diffuse.as_slice()), ("sh_unoccluded", self.unoccluded.as_slice())];
        for (name, layer) in
            [("sh_heightfield", &self.heightfield), ("sh_blockers", &self.blockers), ("sh_specular", &self.specular)]
        {
            if let Some(values) = layer {
                layers.push((name, values.as_slice()));
            }
        }
        layers
    }

    /// The EXR channels of the layers (module doc), SH and colour layers as `colour`; the
    /// frame's `P`, `N` and alpha are the passes' own and not repeated.
    pub fn channels(&self, colour: SampleType) -> Vec<OutputChannel<'_>> {
        let count = self.count();
        let mut channels = Vec::new();
        for (name, values) in self.sh_layers() {
            for k in 0..count {
                let channel = format!("{name}_{}.{}", k - k % 4, ["R", "G", "B", "A"][k % 4]);
                channels.push(OutputChannel::interleaved(channel, colour, values, count, k));
            }
        }
        let (rgb, xyz) = (["R", "G", "B"], ["X", "Y", "Z"]);
        for (layer, names, values, kind) in [
            ("albedo", &rgb[..], self.albedo.as_flattened(), colour),
            ("specular_colour", &rgb, self.specular_colour.as_flattened(), colour),
            ("lamps_diffuse", &rgb, self.lamps_diffuse.as_flattened(), colour),
            ("lamps_specular", &rgb, self.lamps_specular.as_flattened(), colour),
            ("glossy_direction", &xyz, self.glossy_direction.as_flattened(), SampleType::Float),
            ("glossy_lobe", &["V"], &self.glossy_lobe, SampleType::Float),
            ("glossy_weight", &["X", "Y"], self.glossy_weight.as_flattened(), colour),
        ] {
            channels.extend(OutputChannel::layer(layer, names, values, kind));
        }
        for (layer, values) in
            [("sun_lamps_diffuse", &self.sun_lamps_diffuse), ("sun_lamps_specular", &self.sun_lamps_specular)]
        {
            if let Some(values) = values {
                channels.extend(OutputChannel::layer(layer, &rgb, values.as_flattened(), colour));
            }
        }
        if let Some(values) = &self.diffuse_normal {
            channels.extend(OutputChannel::layer("diffuse_normal", &xyz, values.as_flattened(), SampleType::Float));
        }
        if let Some(values) = &self.horizons {
            let sectors = self.horizon_sectors();
            for (k, name) in horizon_channels(sectors).into_iter().enumerate() {
                channels.push(OutputChannel::interleaved(name, SampleType::Half, values, sectors, k));
            }
        }
        channels
    }

    /// The header as the JSON text of [`TRANSFER_ATTRIBUTE`]; EXR text is Latin-1, so
    /// every other character (a file name's) is escaped as JSON `\u` escapes. Fails where
    /// a path it records is not Unicode, which JSON cannot hold.
    pub fn header_text(&self) -> Result<String, String> {
        let json = serde_json::to_string(&self.header).map_err(|e| {
            format!(
                "the transfer header cannot record the scene {} or a file of it ({e}): rename it with Unicode characters",
                self.header.scene.display()
            )
        })?;
        let mut text = String::with_capacity(json.len());
        for c in json.chars() {
            if c.is_ascii() {
                text.push(c);
            } else {
                let mut units = [0u16; 2];
                for unit in c.encode_utf16(&mut units) {
                    text.push_str(&format!("\\u{unit:04x}"));
                }
            }
        }
        Ok(text)
    }

    /// The header of a frame that `logsh render --transfer` wrote, read without its
    /// pixels.
    pub fn read_header(file: &Path) -> Result<TransferHeader, SceneError> {
        let meta = exr::meta::MetaData::read_from_file(file, false)
            .map_err(|e| crate::scene::error::exr_error(file, "a frame with transfer layers", e))?;
        header_of(file, &meta)
    }

    /// Reads the transfer layers of a frame that `logsh render --transfer` wrote.
    pub fn read(file: &Path) -> Result<TransferFrame, SceneError> {
        Self::read_reusing(file, None)
    }
}

/// The channel of sector `k`'s horizon tangents, `horizon.k`.
fn horizon_channel(k: usize) -> String {
    format!("horizon.{k}")
}

/// The channels of `sectors` horizon tangents per pixel, `horizon.0` onwards.
fn horizon_channels(sectors: usize) -> Vec<String> {
    (0..sectors).map(horizon_channel).collect()
}

/// The least half float at or above `tangent` (`>= 0`), as an f32: a horizon kept in the
/// file still bounds the one marched. Infinite for `NaN`, which bounds nothing.
fn half_at_least(tangent: f32) -> f32 {
    if tangent.is_nan() {
        return f32::INFINITY;
    }
    let tangent = tangent.max(0.0);
    let rounded = half::f16::from_f32(tangent);
    if f32::from(rounded) >= tangent {
        return f32::from(rounded);
    }
    // Past the nearest half, a positive finite one: the next half up (infinite past the
    // largest).
    f32::from(half::f16::from_bits(rounded.to_bits() + 1))
}

#[cfg(test)]
mod tests {
    use super::half_at_least;
    use half::f16;

    /// A horizon kept as a half is the least half at or above it, so it still bounds the
    /// one marched: over every half and the f32s between, those past the largest half
    /// infinite, NaN infinite, anything below 0 as 0.
    #[test]
    fn a_kept_horizon_is_the_least_half_at_or_above_it() {
        for bits in 0..0x7c00u16 {
            let half = f32::from(f16::from_bits(bits));
            let next = f32::from(f16::from_bits(bits + 1));
            assert_eq!(half_at_least(half), half, "a half is kept as it is");
            for between in [half + (next - half) * 0.25, half + (next - half) * 0.5, half + (next - half) * 0.75] {
                if between > half && between < next {
                    assert_eq!(half_at_least(between), next, "{between} between {half} and {next}");
                }
            }
        }
        assert_eq!(half_at_least(65504.5), f32::INFINITY);
        assert_eq!(half_at_least(f32::INFINITY), f32::INFINITY);
        assert_eq!(half_at_least(f32::NAN), f32::INFINITY);
        assert_eq!(half_at_least(-0.25), 0.0);
    }
}
