//! Reading a frame's transfer layers back ([`TransferFrame::read_reusing`]): which
//! optional layers the file holds, checked against its header; its channels decoded into
//! the memory of a frame read before; then every value checked, a bad one named by its
//! channel and pixel.

use super::UNRECORDED_SECTORS;
use super::{header_of, horizon_channel, horizon_channels, lobe_code, TransferFrame, TransferHeader};
use crate::scene::exr_read::{read_with_headers, ChannelFile};
use crate::scene::exr_zip::Target;
use crate::scene::SceneError;
use crate::sh::coefficient_count;
use crate::shade::bounce::IndirectParts;
use rayon::prelude::*;
use std::path::Path;

const WHAT: &str = "a frame with transfer layers";

/// The optional layers a file holds, as its header says it must.
struct HeldLayers {
    heightfield_and_blockers: bool,
    specular: bool,
    sun_lamps: bool,
    /// Horizon channels per pixel, 0 where the file holds none.
    horizon_sectors: usize,
    bounce: bool,
    diffuse_normal: bool,
}

impl TransferFrame {
    /// [`read`](Self::read) into the memory of `spare`, a frame read before (of any
    /// size), where there is one; its `P` and `N` where no passes share them any longer.
    /// A frame's layers are 151 MB at 960x540 (`cones`: three transfer layers at order
    /// 4), and freshly allocated each of their 37,000 pages faults as it is first written.
    pub fn read_reusing(file: &Path, spare: Option<TransferFrame>) -> Result<TransferFrame, SceneError> {
        let (bytes, meta) = read_with_headers(file, WHAT)?;
        let header = header_of(file, &meta)?;
        let channels = ChannelFile::new(file, WHAT, bytes, &meta, "sh_diffuse_0.R")?;
        let (width, height) = channels.size();
        let held = HeldLayers::of(file, &header, &channels)?;
        // Every value is written by `fill`, so a spare's old values are left in place.
        let mut frame = Self::reusing(spare, width, height, header, &held);
        let mut targets: Vec<Target> = frame.read_targets().into_iter().map(|(target, _)| target).collect();
        channels.fill(file, WHAT, &mut targets)?;
        drop(targets);
        frame.check_lobes(file)?;
        frame.check_horizons(file)?;
        frame.check_finite(file)?;
        Ok(frame)
    }

    /// A frame of `width` x `height` with the layers `held`, in the memory of `spare`
    /// where it has enough, its values as they were.
    fn reusing(
        spare: Option<TransferFrame>,
        width: usize,
        height: usize,
        header: TransferHeader,
        held: &HeldLayers,
    ) -> TransferFrame {
        let n = width * height;
        let count = coefficient_count(header.sh.order);
        let spare = spare.unwrap_or_else(|| TransferFrame::new(0, 0, header.clone(), false, false, 0));
        let sh_layer = |layer: Option<Vec<f32>>, held: bool| held.then(|| sized(layer.unwrap_or_default(), n * count));
        let colour_layer = |layer: Option<Vec<[f32; 3]>>| held.sun_lamps.then(|| sized(layer.unwrap_or_default(), n));
        let sectors = held.horizon_sectors;
        TransferFrame {
            width,
            height,
            header,
            diffuse: sized(spare.diffuse, n * count),
            unoccluded: sized(spare.unoccluded, n * count),
            heightfield: sh_layer(spare.heightfield, held.heightfield_and_blockers),
            blockers: sh_layer(spare.blockers, held.heightfield_and_blockers),
            specular: sh_layer(spare.specular, held.specular),
            albedo: sized(spare.albedo, n),
            specular_colour: sized(spare.specular_colour, n),
            lamps_diffuse: sized(spare.lamps_diffuse, n),
            lamps_specular: sized(spare.lamps_specular, n),
            sun_lamps_diffuse: colour_layer(spare.sun_lamps_diffuse),
            sun_lamps_specular: colour_layer(spare.sun_lamps_specular),
            glossy_lobe: sized(spare.glossy_lobe, n),
            glossy_direction: sized(spare.glossy_direction, n),
            glossy_weight: sized(spare.glossy_weight, n),
            alpha: sized(spare.alpha, n),
            horizons: (sectors > 0).then(|| sized(spare.horizons.unwrap_or_default(), n * sectors)),
            diffuse_normal: held.diffuse_normal.then(|| sized(spare.diffuse_normal.unwrap_or_default(), n)),
            bounce: held.bounce.then(|| {
                let [heightfield, blockers] = spare.bounce.map(|b| [b.heightfield, b.blockers]).unwrap_or_default();
                IndirectParts { heightfield: sized(heightfield, n), blockers: sized(blockers, n) }
            }),
            position: unshared(spare.position, n),
            normal: unshared(spare.normal, n),
        }
    }

    /// Every layer the file is read into, with its channels, and whether each of its
    /// values must be finite (the lobe codes and horizons have checks of their own, and
    /// `P` and `N` are passed through).
    fn read_targets<'a>(&'a mut self) -> Vec<(Target<'a>, bool)> {
        let count = self.count();
        let sectors = self.horizon_sectors();
        let TransferFrame {
            diffuse,
            unoccluded,
            heightfield,
            blockers,
            specular,
            albedo,
            specular_colour,
            lamps_diffuse,
            lamps_specular,
            sun_lamps_diffuse,
            sun_lamps_specular,
            glossy_lobe,
            glossy_direction,
            glossy_weight,
            alpha,
            horizons,
            diffuse_normal,
            bounce,
            position,
            normal,
            ..
        } = self;
        let sh = |values: &'a mut Vec<f32>, name: &str| sh_target(values, name, count);
        let (rgb, xyz) = (["R", "G", "B"], ["X", "Y", "Z"]);
        let mut targets = vec![sh(diffuse, "sh_diffuse"), sh(unoccluded, "sh_unoccluded")];
        for (layer, name) in [(heightfield, "sh_heightfield"), (blockers, "sh_blockers"), (specular, "sh_specular")] {
            targets.extend(layer.as_mut().map(|values| sh(values, name)));
        }
        for (layer, name) in [
            (albedo, "albedo."),
            (specular_colour, "specular_colour."),
            (lamps_diffuse, "lamps_diffuse."),
            (lamps_specular, "lamps_specular."),
        ] {
            targets.push(named(layer.as_flattened_mut(), name, &rgb));
        }
        targets.push(named(glossy_direction.as_flattened_mut(), "glossy_direction.", &xyz));
        for (layer, name) in [(sun_lamps_diffuse, "sun_lamps_diffuse."), (sun_lamps_specular, "sun_lamps_specular.")] {
            targets.extend(layer.as_mut().map(|values| named(values.as_flattened_mut(), name, &rgb)));
        }
        targets.push(named(glossy_weight.as_flattened_mut(), "glossy_weight.", &["X", "Y"]));
        targets.push(named(alpha, "", &["A"]));
        if let Some(values) = diffuse_normal {
            targets.push(named(values.as_flattened_mut(), "diffuse_normal.", &xyz));
        }
        if let Some(parts) = bounce {
            targets.push(named(parts.heightfield.as_flattened_mut(), "indirect_heightfield.", &rgb));
            targets.push(named(parts.blockers.as_flattened_mut(), "indirect_blockers.", &rgb));
        }
        let mut targets: Vec<_> = targets.into_iter().map(|target| (target, true)).collect();
        targets.push((named(unshared_values(position), "P.", &xyz), false));
        targets.push((named(unshared_values(normal), "N.", &xyz), false));
        targets.push((named(glossy_lobe, "glossy_lobe.", &["V"]), false));
        if let Some(values) = horizons {
            let channels = horizon_channels(sectors).into_iter().enumerate().map(|(k, name)| (name, k)).collect();
            targets.push((Target { values, stride: sectors, channels }, false));
        }
        targets
    }

    /// Each pixel's glossy lobe code is one the header lists, and `sh_specular` is held
    /// where one reads it.
    fn check_lobes(&self, file: &Path) -> Result<(), SceneError> {
        let last = lobe_code::PREFILTERED + self.header.lobes.len() as f32 - 1.0;
        let codes = &self.glossy_lobe;
        if let Some(i) =
            codes.par_iter().position_first(|&c| !(c == c.round() && (0.0..=last.max(lobe_code::SH)).contains(&c)))
        {
            let (x, y) = (i % self.width, i / self.width);
            return Err(SceneError::invalid(
                file,
                format!("glossy_lobe.V is {} at pixel ({x}, {y}), not a lobe of the header", codes[i]),
            ));
        }
        if self.specular.is_none() && codes.par_iter().any(|&c| c >= lobe_code::SH) {
            return Err(SceneError::invalid(file, "its pixels read sh_specular, which it does not hold"));
        }
        Ok(())
    }

    /// A horizon bounds a turned lamp's shadow: one below 0 or not a number would bound
    /// it wrongly (infinite bounds nothing, and is kept where none was marched). Checked a
    /// chunk at a time, then found.
    fn check_horizons(&self, file: &Path) -> Result<(), SceneError> {
        let Some(values) = self.horizons.as_ref().filter(|values| !every_value(values, |x| x >= 0.0)) else {
            return Ok(());
        };
        let sectors = self.horizon_sectors();
        let Some(i) = values.iter().position(|v| !(*v >= 0.0)) else { return Ok(()) };
        let (pixel, k) = (i / sectors, i % sectors);
        Err(SceneError::invalid(
            file,
            format!(
                "channel {} is {} at pixel ({}, {}), where a horizon tangent is at least 0",
                horizon_channels(sectors)[k],
                values[i],
                pixel % self.width,
                pixel / self.width
            ),
        ))
    }

    /// Every value of the layers that must be finite is, or the first that is not is
    /// named by its channel and pixel (rare: a damaged file).
    fn check_finite(&mut self, file: &Path) -> Result<(), SceneError> {
        let width = self.width;
        let targets = self.read_targets();
        let finite = targets.iter().filter(|(_, finite)| *finite).map(|(target, _)| target);
        if finite.clone().all(|target| every_value(target.values, f32::is_finite)) {
            return Ok(());
        }
        let what = finite
            .clone()
            .find_map(|target| {
                let at = target.values.iter().position(|v| !v.is_finite())?;
                let channel = target.channels.iter().find(|(_, offset)| *offset == at % target.stride)?;
                let pixel = at / target.stride;
                Some(format!("channel {} at pixel ({}, {})", channel.0, pixel % width, pixel / width))
            })
            .unwrap_or_else(|| "a transfer layer".into());
        Err(SceneError::NonFinite { file: file.to_path_buf(), what })
    }
}

/// The `count` coefficients per pixel of SH layer `name`: `name_0.R` to `name_0.A`,
/// `name_4.R` onwards.
fn sh_target<'a>(values: &'a mut [f32], name: &str, count: usize) -> Target<'a> {
    let channels = (0..count).map(|k| (format!("{name}_{}.{}", k - k % 4, ["R", "G", "B", "A"][k % 4]), k));
    Target { values, stride: count, channels: channels.collect() }
}

/// The channels `layer` + each of `names`, interleaved per pixel.
fn named<'a>(values: &'a mut [f32], layer: &str, names: &[&str]) -> Target<'a> {
    let channels = names.iter().enumerate().map(|(k, c)| (format!("{layer}{c}"), k)).collect();
    Target { values, stride: names.len(), channels }
}

/// The values of `shared`, which nothing else holds ([`unshared`]).
fn unshared_values(shared: &mut std::sync::Arc<[[f32; 3]]>) -> &mut [f32] {
    std::sync::Arc::get_mut(shared).expect("unshared").as_flattened_mut()
}

impl HeldLayers {
    /// The optional layers of `channels`, which must be those `header` names.
    fn of(file: &Path, header: &TransferHeader, channels: &ChannelFile) -> Result<Self, SceneError> {
        let has_sh = |name: &str| channels.has(&format!("{name}_0.R"));
        let (has_heightfield, has_blockers) = (has_sh("sh_heightfield"), has_sh("sh_blockers"));
        if has_heightfield != has_blockers {
            return Err(SceneError::invalid(file, "has one of sh_heightfield and sh_blockers without the other"));
        }
        if has_heightfield != (header.heightfield && header.blockers) {
            return Err(SceneError::invalid(
                file,
                "holds sh_heightfield and sh_blockers where its header does not name both a height field and \
                 blockers, or lacks them where it does",
            ));
        }
        let sun_lamps = channels.has("sun_lamps_diffuse.R");
        if sun_lamps == header.sun_lamps.is_empty() {
            return Err(SceneError::invalid(
                file,
                "holds sun_lamps_diffuse and sun_lamps_specular where its header lists no Sun lamp, or lacks them \
                 where it does",
            ));
        }
        let diffuse_normal = channels.has("diffuse_normal.X");
        if diffuse_normal == header.open_diffuse.is_empty() {
            return Err(SceneError::invalid(
                file,
                "holds diffuse_normal where its header records no open_diffuse, or lacks it where it does",
            ));
        }
        Ok(Self {
            diffuse_normal,
            heightfield_and_blockers: has_heightfield,
            specular: has_sh("sh_specular"),
            sun_lamps,
            horizon_sectors: horizon_sectors(file, header, channels)?,
            bounce: channels.has("indirect_heightfield.R"),
        })
    }
}

/// The horizon channels per pixel: the sectors the header records (a missing channel is
/// then named as it is read), or in a file that holds the layer without recording them,
/// its channels if they are as many as such a file kept.
fn horizon_sectors(file: &Path, header: &TransferHeader, channels: &ChannelFile) -> Result<usize, SceneError> {
    Ok(match (channels.has(&horizon_channel(0)), header.horizon_sectors, &header.settings) {
        (false, None, _) => 0,
        // Sun lamps, or suns a render with sharp lights takes out of a map, over a field.
        (_, recorded, Some(settings))
            if header.heightfield && (!header.sun_lamps.is_empty() || settings.sharp_lights) =>
        {
            let azimuths = settings.horizon.directions;
            let held = || (0..=azimuths).take_while(|&k| channels.has(&horizon_channel(k))).count();
            match recorded {
                Some(sectors) if (1..=azimuths).contains(&sectors) => sectors,
                Some(sectors) => {
                    return Err(SceneError::invalid(
                        file,
                        format!("keeps its horizons in {sectors} sectors, not 1 to its {azimuths} azimuths"),
                    ))
                }
                None => match held() {
                    held if UNRECORDED_SECTORS.iter().any(|&kept| held == kept.min(azimuths)) => held,
                    held => {
                        return Err(SceneError::invalid(
                            file,
                            format!(
                                "holds {held} horizon channels from horizon.0 without recording its sectors, \
                                 where such a file kept {} of its {azimuths} azimuths",
                                UNRECORDED_SECTORS.map(|kept| kept.min(azimuths).to_string()).join(" or ")
                            ),
                        ))
                    }
                },
            }
        }
        _ => {
            return Err(SceneError::invalid(
                file,
                "holds horizon channels, or records their sectors, where its header lists no Sun lamp and no \
                 sharp lights over a height field, or no settings",
            ))
        }
    })
}

/// Whether `test` holds for every one of `values`: each chunk checked whole, which runs
/// in vector lanes (one value at a time, the finite check was a tenth of a sequence's
/// relight).
fn every_value(values: &[f32], test: impl Fn(f32) -> bool + Sync) -> bool {
    values.par_chunks(1 << 14).all(|chunk| chunk.iter().fold(true, |all, &x| all & test(x)))
}

/// `v` at length `n`, its values left as they are, or `n` zeros where it holds fewer
/// (from the allocator's zeroed pages, which the decoder then writes once).
fn sized<T: Copy + Default>(mut v: Vec<T>, n: usize) -> Vec<T> {
    if v.capacity() < n {
        return vec![T::default(); n];
    }
    v.truncate(n);
    v.resize(n, T::default());
    v
}

/// `shared` where nothing else holds it and it has `n` values, else `n` new ones.
fn unshared(mut shared: std::sync::Arc<[[f32; 3]]>, n: usize) -> std::sync::Arc<[[f32; 3]]> {
    if shared.len() != n || std::sync::Arc::get_mut(&mut shared).is_none() {
        shared = std::iter::repeat_n([0.0f32; 3], n).collect();
    }
    shared
}
