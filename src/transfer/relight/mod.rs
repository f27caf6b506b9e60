//! `logsh relight`: the passes of a frame recomputed from its transfer layers under a
//! light turned, scaled or swapped (the formulas in the [module doc](super)).

mod dots;

use super::layers::{TransferFrame, TransferHeader};
use super::lobe_code;
use crate::scene::light::{equirectangular_to_direction, file_crc, lookup_coordinates};
use crate::scene::{EnvironmentMap, Light, LightSource, SceneError, SunLight};
use crate::shade::compositing::ShadedPasses;
use crate::shade::glossy::{MapLevels, Prefiltered};
use crate::shade::kernel::{glossy_map, occlusion_ratio, open_corrected_channel, visibility_ratio, OpenIrradiance};
use crate::shade::LightWindow;
use clap::ValueEnum;
use dots::*;
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::path::{Path, PathBuf};

/// How the light of a relight differs from the one the frame was rendered with.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RelightOptions {
    /// Another environment map (`--light`), in place of the rendered light; its Mapping
    /// rotation is none, and it is turned as the rendered light was (the render's
    /// `--light-rotation`, which turned the scene's Sun lamps too), then by `rotation`.
    pub light: Option<PathBuf>,
    /// Degrees about Z on top of the rendered turn (`--light-rotation`).
    pub rotation: f64,
    /// The map's strength (`--strength`): the rendered one by default, 1 for `--light`;
    /// it scales a constant or SH light too.
    pub strength: Option<f32>,
}

impl RelightOptions {
    /// Refuses to relight a frame of `header` (read from `frame`) with the map it was
    /// rendered with, `light` built from that map, where its file has changed since the
    /// render ([`TransferHeader::light_file_crc`] against the CRC-32 of the file as
    /// `light` read it): its transfer and lamps were shaded under the old one. Each frame
    /// is checked, those that share a light too. A map given with `--light` is what the
    /// user asks for, and passes.
    pub fn check_rendered_map(
        &self,
        light: &RelightLight,
        header: &TransferHeader,
        frame: &Path,
    ) -> Result<(), SceneError> {
        match (&self.light, &header.light, header.light_file_crc) {
            (None, LightSource::Environment { file, .. }, Some(rendered)) if light.map_crc != Some(rendered) => {
                Err(SceneError::invalid(
                    frame,
                    format!(
                        "the map it was rendered with, {}, has changed since the render; `logsh relight --light {}` \
                         lights it with the map as it is now",
                        file.display(),
                        file.display()
                    ),
                ))
            }
            _ => Ok(()),
        }
    }

    /// The turn about Z beyond the rendered light, whole turns taken out first, exactly
    /// (`%` is exact), so that a vast angle turns as its remainder does: what the light is
    /// turned by ([`Self::source`]) and what light.json records of it.
    pub fn turn_beyond_render(&self) -> f64 {
        self.rotation % 360.0
    }

    /// The light to relight with, from the one `header` records.
    pub fn source(&self, header: &TransferHeader) -> LightSource {
        let degrees = self.turn_beyond_render();
        match (&self.light, &header.light) {
            (Some(file), _) => LightSource::Environment {
                file: file.clone(),
                strength: self.strength.unwrap_or(1.0),
                rotation: [0.0; 3],
                turn: header.light_turn + degrees,
            },
            (None, LightSource::Environment { file, strength, rotation, turn }) => LightSource::Environment {
                file: file.clone(),
                strength: self.strength.unwrap_or(*strength),
                rotation: *rotation,
                turn: turn + degrees,
            },
            (None, LightSource::Constant(c)) => LightSource::Constant(c.map(|v| v * self.strength.unwrap_or(1.0))),
            (None, LightSource::Sh(v)) => {
                let scale = f64::from(self.strength.unwrap_or(1.0));
                let scaled: Vec<[f64; 3]> = v.iter().map(|c| c.map(|x| x * scale)).collect();
                LightSource::Sh(crate::scene::light::turned_sh(&scaled, degrees))
            }
        }
    }
}

/// The light of a relight, ready for the pixels: its SH vector (windowed as the render's
/// was) and its map prefiltered with each of the frame's glossy lobes; with sharp suns
/// ([`Self::with_sharp_suns`]), those of the map's residual, the suns apart.
pub struct RelightLight {
    pub source: LightSource,
    /// The light whole, as the background and water's mirrors read it.
    light: Light,
    /// The suns taken out of the map, as a render's `--sharp-lights auto` takes them
    /// ([`crate::shade::sharp_lights`]), to be shaded per pixel; empty where the SH holds
    /// the whole light.
    sharp_suns: Vec<SunLight>,
    /// Per colour channel, `order^2` coefficients.
    sh: [Vec<f32>; 3],
    /// The same in [`Blocks`].
    blocks: Blocks,
    /// Per lobe of the header; `None` for a light without a map.
    prefiltered: Vec<Option<Prefiltered>>,
    /// Per lobe of the header, the light convolved with its open lobe
    /// ([`open_light_blocks`]).
    open: Vec<Blocks>,
    /// Where the frame's diffuse light is corrected to the map's irradiance
    /// ([`TransferHeader::open_diffuse`]): the light's.
    open_diffuse: Option<OpenDiffuse>,
    /// Whether the suns of its map are taken out ([`Self::with_sharp_suns`]).
    sharp: bool,
    /// What it was built for, to be reused by the next frame of a sequence.
    key: (usize, String, bool, Vec<super::layers::PrefilteredLobe>, Vec<f64>),
    /// The CRC-32 of its map's file as it was read ([`crate::scene::light::file_crc`]).
    map_crc: Option<u32>,
}

impl RelightLight {
    /// Reads and projects `source` for frames of `header`'s convention and lobes; `frame`
    /// is the file `header` came from, named in its errors.
    pub fn new(source: LightSource, header: &TransferHeader, frame: &Path) -> Result<Self, SceneError> {
        Self::build(source, header, frame, false)
    }

    /// [`Self::new`] with the suns of its map taken out as the render takes them
    /// (`--sharp-lights auto`: the same decomposition of the same turned map), the SH
    /// vector and the prefiltered maps made of the residual, as the render's are; the suns
    /// ([`Self::sharp_suns`]) are then shaded from the scene
    /// ([`super::SunLampTurn::shade_again`]). A light without a map, or a map without a
    /// sun, is [`Self::new`]'s.
    pub fn with_sharp_suns(source: LightSource, header: &TransferHeader, frame: &Path) -> Result<Self, SceneError> {
        Self::build(source, header, frame, true)
    }

    fn build(source: LightSource, header: &TransferHeader, frame: &Path, sharp: bool) -> Result<Self, SceneError> {
        let order = header.sh.order;
        let mut map_crc = None;
        let light = match &source {
            LightSource::Environment { file, strength, rotation, turn } => {
                map_crc = file_crc(file);
                if !strength.is_finite() || *strength < 0.0 {
                    return Err(SceneError::invalid(file, format!("strength {strength} is not a finite value >= 0")));
                }
                let map = EnvironmentMap::read(file).map_err(|e| match &header.light {
                    LightSource::Environment { file: rendered, .. } if rendered == file => SceneError::invalid(
                        frame,
                        format!("the map it was rendered with cannot be read ({e}); relight with --light MAP to light it with another"),
                    ),
                    _ => e,
                })?;
                Light::Environment { map: map.oriented(*rotation, *turn), strength: *strength }
            }
            LightSource::Constant(c) => Light::Constant(*c),
            // Whole, as the render holds it: the transfer dots its first `order^2`
            // coefficients (zeros past a shorter light's), the background and the mirrors
            // read every one.
            LightSource::Sh(v) => Light::Sh(v.clone()),
        };
        let window = LightWindow::from_str(&header.light_window, true).map_err(|_| {
            SceneError::invalid(frame, format!("its header names an unknown light window \"{}\"", header.light_window))
        })?;
        // What the SH and the glossy lobes hold: the residual where suns are taken out.
        let (residual, sharp_suns) = match &light {
            Light::Environment { map, strength } if sharp => {
                let split = crate::shade::sharp_lights::extract_suns(map, *strength);
                (Some(Light::Environment { map: split.residual, strength: *strength }), split.suns)
            }
            _ => (None, Vec::new()),
        };
        let held = residual.as_ref().filter(|_| !sharp_suns.is_empty()).unwrap_or(&light);
        let mut coefficients = held.sh_coefficients(order);
        window.apply(order, &mut coefficients);
        let sh: [Vec<f32>; 3] = [0, 1, 2].map(|k| coefficients.iter().map(|c| c[k] as f32).collect());
        let blocks = blocks_of(&sh);
        let levels = (!header.lobes.is_empty())
            .then(|| glossy_map(held))
            .flatten()
            .map(|(map, strength)| MapLevels::new(&map, strength, header.sky_only));
        let prefiltered =
            header.lobes.iter().map(|lobe| levels.as_ref().map(|levels| levels.prefilter(lobe.lobe))).collect();
        let open = header.lobes.iter().map(|lobe| open_light_blocks(&sh, &lobe.open)).collect();
        let open_diffuse =
            (!header.open_diffuse.is_empty()).then(|| glossy_map(held)).flatten().map(|(map, strength)| OpenDiffuse {
                irradiance: OpenIrradiance::new(&map, strength),
                open: open_light_blocks(&sh, &header.open_diffuse),
            });
        let key =
            (order, header.light_window.clone(), header.sky_only, header.lobes.clone(), header.open_diffuse.clone());
        Ok(Self { source, light, sharp_suns, sh, blocks, prefiltered, open, open_diffuse, sharp, key, map_crc })
    }

    /// The suns taken out of its map, shaded per pixel from the scene, not by the SH
    /// ([`Self::with_sharp_suns`]).
    pub fn sharp_suns(&self) -> &[SunLight] {
        &self.sharp_suns
    }

    /// The suns a render's `--sharp-lights auto` would take out of this light's map and
    /// shade with their own sharp shadows ([`crate::shade::sharp_lights`]), each with its
    /// share of the map's power, which this light holds in SH with the rest of the map;
    /// empty for a light without a map or one that takes them out itself
    /// ([`Self::with_sharp_suns`]). Held in SH their shadows come out soft: on the
    /// HDRI-sun primitives of docs/performance-log.md the relit frame is 0.090 from Cycles against the
    /// render's 0.015. The decomposition is the render's, so it costs what the render's
    /// first frame pays for it.
    pub fn suns_in_sh(&self) -> Vec<(SunLight, f64)> {
        match &self.light {
            Light::Environment { map, strength } if !self.sharp => {
                let split = crate::shade::sharp_lights::extract_suns(map, *strength);
                split.suns.into_iter().zip(split.shares).collect()
            }
            _ => Vec::new(),
        }
    }

    /// Whether this light serves frames of `header` relit from `source`, its suns taken
    /// out where `sharp` ([`Self::with_sharp_suns`]).
    pub fn serves(&self, source: &LightSource, header: &TransferHeader, sharp: bool) -> bool {
        self.source == *source
            && self.sharp == sharp
            && self.key
                == (
                    header.sh.order,
                    header.light_window.clone(),
                    header.sky_only,
                    header.lobes.clone(),
                    header.open_diffuse.clone(),
                )
    }
}

/// The light of a frame's open receiver, by which a relight corrects its diffuse light
/// as the render did ([`crate::shade::kernel::open_corrected_channel`]).
struct OpenDiffuse {
    /// `E(n) / pi` of the light's map.
    irradiance: OpenIrradiance,
    /// The light convolved with the open receiver's ZH ([`open_light_blocks`]).
    open: Blocks,
}

impl OpenDiffuse {
    /// `lit`, the diffuse light `exp*(V + D) . L`, corrected at the normal `n`.
    ///
    /// # Safety
    /// The processor has what `D` needs ([`Dots::dot`]).
    #[inline(always)]
    unsafe fn corrected<D: Dots>(&self, lit: [f32; 3], n: [f32; 3], order: usize) -> [f32; 3] {
        let n = n.map(f64::from);
        // SAFETY: the caller holds `D`'s contract.
        let open = unsafe { open_light::<D>(&self.open, order, n) };
        let full = self.irradiance.at(n);
        [0, 1, 2].map(|c| open_corrected_channel(f64::from(lit[c]), f64::from(open[c]), full[c]) as f32)
    }
}

/// An equirectangular grid of radiance in the orientation of [`EnvironmentMap`], read
/// bilinearly (the viewer's copy of a map the relight reads).
pub struct SampledMap {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<[f32; 3]>,
}

impl SampledMap {
    /// `radiance` at the texel centres of a `width` x `height` grid.
    fn sample(width: usize, height: usize, radiance: impl Fn([f64; 3]) -> [f32; 3] + Sync) -> Self {
        Self::sample_rows(width, height, |row| 1.0 - (row as f64 + 0.5) / height as f64, radiance)
    }

    /// `radiance` on a grid whose first row is the zenith and last the nadir, `height`
    /// rows evenly apart from pole to pole: a receiver facing straight up, as floors do,
    /// reads it exactly.
    fn sample_from_pole_to_pole(width: usize, height: usize, radiance: impl Fn([f64; 3]) -> [f32; 3] + Sync) -> Self {
        Self::sample_rows(width, height, |row| 1.0 - row as f64 / (height - 1).max(1) as f64, radiance)
    }

    /// `radiance` at the column centres of a `width` x `height` grid, row `r` at the
    /// map's `v = v_of(r)`.
    fn sample_rows(
        width: usize,
        height: usize,
        v_of: impl Fn(usize) -> f64 + Sync,
        radiance: impl Fn([f64; 3]) -> [f32; 3] + Sync,
    ) -> Self {
        let texels = (0..width * height)
            .into_par_iter()
            .map(|i| {
                let (column, row) = (i % width, i / width);
                radiance(equirectangular_to_direction((column as f64 + 0.5) / width as f64, v_of(row)))
            })
            .collect();
        Self { width, height, texels }
    }
}

/// The widest grid [`RelightLight::sampled_maps`] gives a map (a preview's reflections).
pub const SAMPLED_MAP_WIDTH: usize = 1024;

/// The grid of the open lobes' light: band-limited at order 8 or less, so a texel every
/// 5.6 degrees holds it to bilinear accuracy.
const OPEN_LIGHT_GRID: [usize; 2] = [64, 32];

/// The grid of the open receiver's light by normal, from pole to pole
/// ([`RelightLight::sampled_maps`]), which the viewer reads only for the change a turn
/// makes to each pixel's exact value: a texel every 1.4 degrees holds its bands
/// bilinearly.
const OPEN_DIFFUSE_GRID: [usize; 2] = [256, 129];

impl RelightLight {
    /// The light's SH vector per colour channel, as the relight dots it.
    pub fn sh(&self) -> &[Vec<f32>; 3] {
        &self.sh
    }

    /// What `logsh relight` writes beside each frame (`<frame>.light.json`): the light's
    /// source, its turn about Z beyond the frame's rendered light (`--light-rotation`,
    /// whole turns taken out), and its SH vector, RGB per coefficient in the header's
    /// convention, which a compositor dots with the transfer layers after turning it back
    /// by that turn (docs/compositing.md: an `sh` source records none of its own); with
    /// the suns taken out of its map ([`Self::sharp_suns`], their directions), the
    /// residual's.
    pub fn description(&self, turned_from_frame: f64) -> serde_json::Value {
        // A map's path as text, made absolute (the file is read from anywhere): JSON holds
        // no path that is not Unicode, which is written with U+FFFD for what does not
        // decode (the light's SH vector is what the file is for).
        let source = match &self.source {
            LightSource::Environment { file, strength, rotation, turn } => {
                let file = std::path::absolute(file).unwrap_or_else(|_| file.clone());
                serde_json::json!({"environment": {
                    "file": file.to_string_lossy(), "strength": strength, "rotation": rotation, "turn": turn,
                }})
            }
            other => serde_json::to_value(other).unwrap_or_default(),
        };
        serde_json::json!({
            "source": source,
            "turned_from_frame": turned_from_frame,
            "order": self.key.0,
            "light_window": self.key.1,
            // RGB per coefficient: of the residual where suns were taken out.
            "sh": (0..self.sh[0].len()).map(|k| self.sh.each_ref().map(|channel| channel[k])).collect::<Vec<_>>(),
            // The suns taken out and shaded sharp, which the SH vector does not hold.
            "sharp_suns": self.sharp_suns.iter().map(|sun| {
                let [azimuth, elevation] = sun.azimuth_elevation();
                serde_json::json!({"azimuth": azimuth, "elevation": elevation})
            }).collect::<Vec<_>>(),
        })
    }

    /// What the glossy lookups read, as grids: the light itself (lobe code 1), then each
    /// prefiltered lobe's map, then each lobe's open light `max(open_j(R) . L, 0)`; then,
    /// where the frame's diffuse light is corrected to the map's irradiance
    /// ([`Self::corrects_diffuse`]), `E(n) / pi` and the open receiver's light
    /// `max(open(n) . L, 0)` by normal, on grids from pole to pole. Maps wider than
    /// [`SAMPLED_MAP_WIDTH`] are resampled to it.
    pub fn sampled_maps(&self, order: usize) -> Vec<SampledMap> {
        let size = |width: usize, height: usize| {
            if width > SAMPLED_MAP_WIDTH {
                (SAMPLED_MAP_WIDTH, (height * SAMPLED_MAP_WIDTH / width).max(1))
            } else {
                (width, height)
            }
        };
        let (width, height) = match &self.light {
            Light::Environment { map, .. } => size(map.width, map.height),
            _ => (OPEN_LIGHT_GRID[0], OPEN_LIGHT_GRID[1]),
        };
        let mut maps = vec![SampledMap::sample(width, height, |d| self.light.radiance(d))];
        for prefiltered in &self.prefiltered {
            maps.push(match prefiltered {
                Some(map) => {
                    let (width, height) = size(map.width, map.height);
                    SampledMap::sample(width, height, |d| map.lookup(d))
                }
                None => SampledMap { width: 1, height: 1, texels: vec![[0.0; 3]] },
            });
        }
        for open in &self.open {
            let [width, height] = OPEN_LIGHT_GRID;
            // SAFETY: the portable dots need no processor feature.
            maps.push(SampledMap::sample(width, height, |d| unsafe { open_light::<PortableDots>(open, order, d) }));
        }
        if self.open_diffuse.is_some() {
            let [width, height] = OPEN_DIFFUSE_GRID;
            for k in 0..2 {
                maps.push(SampledMap::sample_from_pole_to_pole(width, height, |d| {
                    self.open_diffuse_at(order, d).map_or([0.0; 3], |v| v[k])
                }));
            }
        }
        maps
    }

    /// Whether it corrects the frames' diffuse light to its map's irradiance, as their
    /// render did ([`TransferHeader::open_diffuse`]).
    pub fn corrects_diffuse(&self) -> bool {
        self.open_diffuse.is_some()
    }

    /// At a receiver of normal `n`, the open receiver's light in full, `E(n) / pi`, and
    /// in log-SH, `max(open(n) . L, 0)`, per colour channel, by which a frame of SH order
    /// `order` is corrected ([`Self::corrects_diffuse`]).
    pub fn open_diffuse_at(&self, order: usize, n: [f64; 3]) -> Option<[[f32; 3]; 2]> {
        let diffuse = self.open_diffuse.as_ref()?;
        // SAFETY: the portable dots need no processor feature.
        let open = unsafe { open_light::<PortableDots>(&diffuse.open, order, n) };
        Some([diffuse.irradiance.at(n).map(|c| c as f32), open])
    }
}

/// One relit pixel.
#[derive(Clone, Copy)]
struct Relit {
    diffuse: [f32; 3],
    specular: [f32; 3],
    environment: [f32; 3],
    visibility: [f32; 3],
}

/// Pixels per parallel task, at most.
const CHUNK: usize = 1024;

/// Pixels per parallel task, at least.
const SMALLEST_CHUNK: usize = 256;

/// Pixels per parallel task for a frame of `pixels`: eight tasks per thread where chunks
/// of [`SMALLEST_CHUNK`] to [`CHUNK`] pixels allow. A frame's glossy pixels gather in a
/// few chunks and cost two to four times the others, so a small frame on many threads
/// waits for those chunks: on 16 threads (Intel Xeon), `glossy` and its Phong-floor
/// variant at 240x135 were relit 18x to 21x and 21x to 24x faster than shaded in chunks
/// of 1024 and 24x to 27x and 25x in chunks of 256 (three alternating runs of
/// `relight_accuracy`); at 960x540, and on 2 threads, the chunks stay at 1024.
fn chunk_size(pixels: usize) -> usize {
    (pixels / (8 * rayon::current_num_threads())).clamp(SMALLEST_CHUNK, CHUNK)
}

/// The passes of `frame` under `light` ([`RelightLight::new`] from the frame's header).
pub fn relight(frame: &TransferFrame, light: &RelightLight) -> ShadedPasses {
    relight_reusing(frame, light, None)
}

/// [`relight`], written into the memory of `spare`, the passes of an earlier frame (of
/// any size), where there is one.
///
/// A frame's passes are 33 MB at 960x540. Freshly allocated, each of their 8,100 pages
/// faults as it is first written, which makes a relight about twice as long as one into
/// the passes of the frame before.
pub fn relight_reusing(frame: &TransferFrame, light: &RelightLight, spare: Option<ShadedPasses>) -> ShadedPasses {
    #[cfg(target_arch = "x86_64")]
    if *crate::x86::AVX2_FMA {
        let chunk = if *crate::x86::WIDE_REGISTERS { relight_chunk_wide } else { relight_chunk_avx2 };
        // SAFETY: the processor has AVX2 and FMA, and AVX-512F and AVX-512VL for the wide
        // build.
        return unsafe { relight_by(frame, light, chunk, spare) };
    }
    // SAFETY: the portable dots need no processor feature.
    unsafe { relight_by(frame, light, relight_chunk::<PortableDots>, spare) }
}

/// A chunk of pixels relit ([`relight_chunk`] in one build).
type ChunkRelight = unsafe fn(&TransferFrame, &RelightLight, usize, RelitChunk);

/// [`relight_reusing`], each chunk by `chunk`.
///
/// # Safety
/// The processor has what `chunk` needs.
unsafe fn relight_by(
    frame: &TransferFrame,
    light: &RelightLight,
    chunk: ChunkRelight,
    spare: Option<ShadedPasses>,
) -> ShadedPasses {
    let n = frame.width * frame.height;
    let size = chunk_size(n);
    let (beauty, colours, terms) = match spare {
        Some(p) => (
            p.beauty,
            [p.diffuse, p.specular, p.environment],
            [p.visibility, p.visibility_heightfield, p.visibility_blockers],
        ),
        None => Default::default(),
    };
    let mut beauty = unwritten(beauty, n);
    let [mut diffuse, mut specular, mut environment] = colours.map(|v| unwritten(v, n));
    let [mut visibility, mut heightfield, mut blockers] = terms.map(|v| unwritten(v, n));
    // Every pass is written in place, once (the frame's outputs are tens of MB at 960x540:
    // gathering them per pixel first doubled the memory traffic, and zeroing them first
    // cost a tenth of a relight).
    (
        beauty.par_chunks_mut(size),
        diffuse.par_chunks_mut(size),
        specular.par_chunks_mut(size),
        environment.par_chunks_mut(size),
        visibility.par_chunks_mut(size),
        heightfield.par_chunks_mut(size),
        blockers.par_chunks_mut(size),
    )
        .into_par_iter()
        .enumerate()
        .for_each(|(index, (beauty, diffuse, specular, environment, visibility, heightfield, blockers))| {
            let out = RelitChunk { beauty, diffuse, specular, environment, visibility, heightfield, blockers };
            // SAFETY: the caller vouches for the processor.
            unsafe { chunk(frame, light, index * size, out) };
        });
    // SAFETY: the chunks cover every pixel, and `relight_chunk` writes every element of
    // its chunk of each pass.
    let mut passes = unsafe {
        ShadedPasses {
            width: frame.width,
            height: frame.height,
            beauty: written(beauty),
            diffuse: written(diffuse),
            specular: written(specular),
            environment: written(environment),
            indirect: vec![[0.0; 3]; n],
            indirect_heightfield: vec![[0.0; 3]; n],
            indirect_blockers: vec![[0.0; 3]; n],
            visibility: written(visibility),
            visibility_heightfield: written(heightfield),
            visibility_blockers: written(blockers),
            position: frame.position.clone(),
            normal: frame.normal.clone(),
        }
    };
    // The render's bounce light, kept as rendered (docs/method/bounce-light.md: what turning
    // the light does to it).
    if let Some(bounce) = &frame.bounce {
        passes.add_indirect(bounce.clone());
    }
    passes
}

/// `n` elements in the memory of `v` (new memory where it holds fewer), to be written once
/// each before [`written`] hands them out.
fn unwritten<T: Copy>(v: Vec<T>, n: usize) -> Vec<MaybeUninit<T>> {
    let mut v = if v.capacity() < n {
        Vec::with_capacity(n)
    } else {
        let mut v = std::mem::ManuallyDrop::new(v);
        // SAFETY: `MaybeUninit<T>` has `T`'s layout, and the allocation passes to the new
        // vector unchanged.
        unsafe { Vec::from_raw_parts(v.as_mut_ptr().cast::<MaybeUninit<T>>(), v.len(), v.capacity()) }
    };
    v.truncate(n);
    v.resize_with(n, MaybeUninit::uninit);
    v
}

/// The elements of `v`, every one written.
///
/// # Safety
/// Every element of `v` has been written.
unsafe fn written<T>(v: Vec<MaybeUninit<T>>) -> Vec<T> {
    let mut v = std::mem::ManuallyDrop::new(v);
    // SAFETY: `MaybeUninit<T>` has `T`'s layout, and the caller vouches that every element
    // is initialised; the allocation passes to the new vector unchanged.
    unsafe { Vec::from_raw_parts(v.as_mut_ptr().cast::<T>(), v.len(), v.capacity()) }
}

/// One chunk of every pass, from pixel `first` on, each element to be written once.
struct RelitChunk<'a> {
    beauty: &'a mut [MaybeUninit<[f32; 4]>],
    diffuse: &'a mut [MaybeUninit<[f32; 3]>],
    specular: &'a mut [MaybeUninit<[f32; 3]>],
    environment: &'a mut [MaybeUninit<[f32; 3]>],
    visibility: &'a mut [MaybeUninit<f32>],
    heightfield: &'a mut [MaybeUninit<f32>],
    blockers: &'a mut [MaybeUninit<f32>],
}

#[cfg(target_arch = "x86_64")]
crate::x86::with_wide_registers! {
    /// [`relight_chunk`] compiled for AVX2 and FMA, its dot products in those registers;
    /// `relight_chunk_wide` is the same with AVX-512's 32 registers where the processor
    /// has them ([`crate::x86`]), with the same bits (`cmp` of relit frames).
    unsafe fn relight_chunk_avx2 / relight_chunk_wide(frame: &TransferFrame, light: &RelightLight, first: usize, out: RelitChunk) {
        // SAFETY: this function's features are what `Avx2Dots` needs.
        unsafe { relight_chunk::<Avx2Dots>(frame, light, first, out) }
    }
}

/// The pixels of one chunk, from pixel `first` on, at most [`CHUNK`] of them.
///
/// The lookup coordinates of the glossy directions (in the map and the prefiltered maps)
/// come first, in a loop of their own: free of branches, it runs in vector lanes, four
/// pixels at a time, with the same operations, so the same bits, as one pixel at a time (a
/// frame all glossy relit about 15 % faster). A chunk in which no pixel looks a map up
/// skips that loop and its reads: on 16 threads of an Intel Xeon, the all-diffuse
/// `spheres` was relit 20x to 24x faster than the GPU shaded it, where it was 16x to 21x
/// (`relight_accuracy --device gpu`, three alternating runs each). The prefiltered maps
/// are read in a loop of their own after it, whose reads no longer wait behind each
/// pixel's dot products (the same bits). Then the open lobes' light of the pixels that need it ([`Dots::open_lights`]),
/// eight at a time where the processor has AVX2, then the pixels.
///
/// # Safety
/// The processor has what `D` needs ([`Dots::dot`]).
#[inline(always)]
unsafe fn relight_chunk<D: Dots>(frame: &TransferFrame, light: &RelightLight, first: usize, out: RelitChunk) {
    let mut coordinates = [[0.0f64; 2]; CHUNK];
    let mut prefiltered = [[0.0f32; 3]; CHUNK];
    let codes = &frame.glossy_lobe[first..first + out.beauty.len()];
    // What `glossy_term` reads a map for: the mirror and the prefiltered lobes.
    if codes.iter().any(|&code| code != lobe_code::NONE && code != lobe_code::SH) {
        let directions = &frame.glossy_direction[first..first + out.beauty.len()];
        for (uv, d) in coordinates.iter_mut().zip(directions) {
            *uv = lookup_coordinates(d.map(f64::from));
        }
        for ((read, &code), &uv) in prefiltered.iter_mut().zip(codes).zip(&coordinates) {
            if code >= lobe_code::PREFILTERED {
                if let Some(map) = &light.prefiltered[(code - lobe_code::PREFILTERED) as usize] {
                    *read = map.lookup_at(uv);
                }
            }
        }
    }
    let mut open = [[0.0f32; 3]; CHUNK];
    // SAFETY: the caller holds `D`'s contract.
    unsafe { D::open_lights(frame, light, first, &mut open[..out.beauty.len()]) };
    for j in 0..out.beauty.len() {
        let i = first + j;
        // SAFETY: the caller holds `D`'s contract.
        let glossy = unsafe { glossy_term::<D>(frame, light, i, coordinates[j], prefiltered[j], open[j]) };
        // SAFETY: the caller holds `D`'s contract.
        let p = unsafe { relit_pixel::<D>(frame, light, i, glossy) };
        let (d, s, e) = (p.diffuse, p.specular, p.environment);
        out.beauty[j].write([d[0] + s[0] + e[0], d[1] + s[1] + e[1], d[2] + s[2] + e[2], frame.alpha[i]]);
        out.diffuse[j].write(d);
        out.specular[j].write(s);
        out.environment[j].write(e);
        let [visibility, heightfield, blockers] = p.visibility;
        out.visibility[j].write(visibility);
        out.heightfield[j].write(heightfield);
        out.blockers[j].write(blockers);
    }
}

/// `G` of pixel `i` of `frame` under `light` (the module doc's formulas), before the
/// specular colour, its prefiltered lobe's map read at its `coordinates` already
/// (`prefiltered`). Written without closures, as [`relit_pixel`] is.
///
/// # Safety
/// The processor has what `D` needs ([`Dots::dot`]).
#[inline(always)]
unsafe fn glossy_term<D: Dots>(
    frame: &TransferFrame,
    light: &RelightLight,
    i: usize,
    coordinates: [f64; 2],
    prefiltered: [f32; 3],
    open: [f32; 3],
) -> [f32; 3] {
    let code = frame.glossy_lobe[i];
    if code == lobe_code::NONE {
        return [0.0; 3];
    }
    let count = frame.count();
    let at = i * count..(i + 1) * count;
    if code == lobe_code::MIRROR {
        light.light.radiance_at(frame.glossy_direction[i].map(f64::from), coordinates)
    } else if code == lobe_code::SH {
        D::dot(&light.blocks, &frame.specular.as_deref().expect("checked on reading")[at])
    } else {
        let j = (code - lobe_code::PREFILTERED) as usize;
        let [cone, sh_weight] = frame.glossy_weight[i];
        let (cone, sh_weight) = (f64::from(cone), f64::from(sh_weight));
        let by_sh = if sh_weight > 0.0 {
            let shadowed = D::dot(&light.blocks, &frame.specular.as_deref().expect("checked on reading")[at]);
            occlusion_ratio(shadowed, open)
        } else {
            0.0
        };
        let weight = cone + sh_weight * by_sh;
        match &light.prefiltered[j] {
            Some(_) => [
                (f64::from(prefiltered[0]) * weight) as f32,
                (f64::from(prefiltered[1]) * weight) as f32,
                (f64::from(prefiltered[2]) * weight) as f32,
            ],
            None => [0.0; 3],
        }
    }
}

/// Pixel `i` of `frame` under `light`, its glossy term `glossy` ([`glossy_term`]).
/// Written without closures, so that all of it is inlined into [`relight_chunk_avx2`]
/// and compiled for AVX2 there.
///
/// # Safety
/// The processor has what `D` needs ([`Dots::dot`]).
#[inline(always)]
unsafe fn relit_pixel<D: Dots>(frame: &TransferFrame, light: &RelightLight, i: usize, glossy: [f32; 3]) -> Relit {
    let count = frame.count();
    let at = i * count..(i + 1) * count;
    let (albedo, colour) = (frame.albedo[i], frame.specular_colour[i]);
    let (diffuse, unoccluded) = (&frame.diffuse[at.clone()], &frame.unoccluded[at.clone()]);
    let (lit, unoccluded, parts) = match (&frame.heightfield, &frame.blockers) {
        (Some(h), Some(b)) => {
            let [lit, unoccluded, h, b] = D::dots(&light.blocks, [diffuse, unoccluded, &h[at.clone()], &b[at]]);
            (lit, unoccluded, Some([h, b]))
        }
        _ => {
            let [lit, unoccluded] = D::dots(&light.blocks, [diffuse, unoccluded]);
            (lit, unoccluded, None)
        }
    };
    let light_of = match (&light.open_diffuse, &frame.diffuse_normal) {
        // SAFETY: the caller holds `D`'s contract.
        (Some(open), Some(normals)) => unsafe { open.corrected::<D>(lit, normals[i], frame.order()) },
        _ => lit,
    };
    let lamps = frame.lamps_diffuse[i];
    let diffuse =
        [albedo[0] * light_of[0] + lamps[0], albedo[1] * light_of[1] + lamps[1], albedo[2] * light_of[2] + lamps[2]];
    let lamps = frame.lamps_specular[i];
    let reflected = [colour[0] * glossy[0], colour[1] * glossy[1], colour[2] * glossy[2]];
    let (specular, environment) = if frame.alpha[i] > 0.0 {
        ([reflected[0] + lamps[0], reflected[1] + lamps[1], reflected[2] + lamps[2]], [0.0; 3])
    } else {
        ([0.0; 3], reflected)
    };
    let visibility = visibility_ratio(lit, unoccluded);
    let parts = match parts {
        Some([h, b]) => [visibility_ratio(h, unoccluded), visibility_ratio(b, unoccluded)],
        _ if frame.header.heightfield => [visibility, 1.0],
        _ if frame.header.blockers => [1.0, visibility],
        _ => [1.0, 1.0],
    };
    Relit { diffuse, specular, environment, visibility: [visibility, parts[0], parts[1]] }
}

/// The synthetic dunes (height field, blockers, a Phong sphere, water and a sky),
/// frame 1 shaded with its transfer, written and read back, and its light turned 30
/// deg; the directory holds the frame (`transfer.exr`).
#[cfg(test)]
pub(crate) fn relit_dunes() -> (tempfile::TempDir, TransferFrame, RelightLight) {
    let dir = tempfile::tempdir().unwrap();
    let options = crate::synth::ExampleOptions { width: 96, height: 54, ..Default::default() };
    let scene = crate::synth::example("dunes", options).unwrap();
    crate::synth::write_scene(dir.path(), &scene).unwrap();
    let scene = crate::scene::Scene::load(dir.path()).unwrap();
    let frame = scene.frame(1).unwrap();
    let settings = crate::shade::ShadingSettings { sharp_lights: false, ..Default::default() };
    let (passes, transfer) = super::shade_with_transfer(&scene, &frame, &settings).unwrap();
    let file = dir.path().join("transfer.exr");
    let half = crate::scene::output::SampleType::Half;
    crate::render::write_passes_with_transfer(&file, &passes, &transfer, half).unwrap();
    let transfer = TransferFrame::read(&file).unwrap();
    let options = super::RelightOptions { rotation: 30.0, ..Default::default() };
    let light = RelightLight::new(options.source(&transfer.header), &transfer.header, &file).unwrap();
    assert!(light.prefiltered.iter().any(Option::is_some), "a prefiltered lobe is read");
    (dir, transfer, light)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sh::coefficient_count;
    use crate::shade::kernel::open_lit;

    /// Every pass of `p`, as bits.
    fn bits(p: &ShadedPasses) -> Vec<u32> {
        let colours = [&p.diffuse, &p.specular, &p.environment].map(|v| v.as_flattened().to_vec()).concat();
        let terms = [&p.visibility, &p.visibility_heightfield, &p.visibility_blockers].map(|v| v.to_vec()).concat();
        [p.beauty.as_flattened(), &colours, &terms].concat().iter().map(|v| v.to_bits()).collect()
    }

    /// The AVX2 build of a relight and the wide one ([`crate::x86`]) write the same bits in
    /// every pass.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn both_builds_of_a_relight_write_the_same_bits() {
        if !(*crate::x86::AVX2_FMA && *crate::x86::WIDE_REGISTERS) {
            eprintln!("skipped: this processor has no AVX-512F and AVX-512VL, so one build only");
            return;
        }
        let (_dir, transfer, light) = relit_dunes();
        // SAFETY: the processor has AVX2, FMA, AVX-512F and AVX-512VL (checked above).
        let [avx2, wide] = [relight_chunk_avx2 as ChunkRelight, relight_chunk_wide]
            .map(|chunk| unsafe { relight_by(&transfer, &light, chunk, None) });
        assert_eq!(bits(&avx2), bits(&wide));
    }

    /// A relight writes the same bits whatever its chunks ([`chunk_size`]): on one thread
    /// (chunks of 648 pixels here) and on 16 (256).
    #[test]
    fn a_relight_is_the_same_on_any_number_of_threads() {
        let (_dir, transfer, light) = relit_dunes();
        let [one, many] = [1, 16].map(|threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let size = pool.install(|| chunk_size(transfer.width * transfer.height));
            (size, bits(&pool.install(|| relight(&transfer, &light))))
        });
        assert_eq!((one.0, many.0), (648, SMALLEST_CHUNK));
        assert!(one.1 == many.1, "the passes differ");
    }

    /// A relight into the memory of other passes (`relight_reusing`, as `logsh relight`
    /// relights a sequence) writes every value of every pass, as a fresh relight does,
    /// whatever those passes held or their size.
    #[test]
    fn a_relight_into_spare_passes_is_a_fresh_relight() {
        let (_dir, transfer, light) = relit_dunes();
        let fresh = relight(&transfer, &light);
        for scale in [0.0, 0.5, 1.0, 2.0] {
            let n = (transfer.width as f64 * transfer.height as f64 * scale) as usize;
            let nan = f32::NAN;
            let spare = ShadedPasses {
                width: 1,
                height: n,
                beauty: vec![[nan; 4]; n],
                diffuse: vec![[nan; 3]; n],
                specular: vec![[nan; 3]; n],
                environment: vec![[nan; 3]; n],
                indirect: vec![[nan; 3]; n],
                indirect_heightfield: vec![[nan; 3]; n],
                indirect_blockers: vec![[nan; 3]; n],
                visibility: vec![nan; n],
                visibility_heightfield: vec![nan; n],
                visibility_blockers: vec![nan; n],
                position: std::sync::Arc::from([]),
                normal: std::sync::Arc::from([]),
            };
            let reused = relight_reusing(&transfer, &light, Some(spare));
            assert_eq!((reused.width, reused.height), (fresh.width, fresh.height));
            assert!(bits(&reused) == bits(&fresh), "spare passes scaled {scale}: the passes differ");
            assert!(std::sync::Arc::ptr_eq(&reused.position, &transfer.position));
        }
    }

    /// A pixel's dot products taken together are each taken alone, bit for bit in the
    /// AVX2 build (the same sums in the same order) and in the portable one, at every
    /// order (whole blocks and a tail), with negative sums clamped.
    #[test]
    fn the_combined_dots_are_the_single_dots() {
        for order in crate::sh::MIN_ORDER..=crate::sh::MAX_ORDER {
            let count = coefficient_count(order);
            let wave = |phase: f32| (0..count).map(move |k| (phase + 1.3 * k as f32).sin());
            let light: [Vec<f32>; 3] = [0.2f32, 0.9, 2.1].map(|p| wave(p).collect());
            let blocks = blocks_of(&light);
            let transfers: Vec<Vec<f32>> = [0.4f32, 1.7, 2.9, 5.3].iter().map(|&p| wave(p).collect()).collect();
            let [a, b, c, d] = [0, 1, 2, 3].map(|k| transfers[k].as_slice());
            // SAFETY: the portable dots need no processor feature.
            unsafe {
                assert_eq!(
                    PortableDots::dots(&blocks, [a, b, c, d]),
                    [a, b, c, d].map(|t| PortableDots::dot(&blocks, t))
                );
            }
            #[cfg(target_arch = "x86_64")]
            if *crate::x86::AVX2_FMA {
                // SAFETY: the processor has AVX2 and FMA.
                unsafe {
                    let single = [a, b, c, d].map(|t| Avx2Dots::dot(&blocks, t));
                    assert!(single.iter().flatten().any(|&v| v == 0.0), "a clamped sum at order {order}");
                    assert_eq!(Avx2Dots::dots(&blocks, [a, b, c, d]), single, "order {order}");
                    assert_eq!(Avx2Dots::dots(&blocks, [a, b]), [single[0], single[1]], "order {order}");
                    assert_eq!(Avx2Dots::dots(&blocks, [c]), [single[2]], "order {order}");
                }
            }
        }
    }

    /// The open lobe's light from the convolved blocks is the kernel's `open_lit` (the
    /// lobe turned to `R`, then dotted with the light) to 1e-6 of it, at every order,
    /// along 500 directions spread over the sphere, in both builds of the dot products and
    /// in the lanes of a chunk's open lights (in every lane, beside other directions).
    #[test]
    fn the_convolved_open_light_is_the_turned_lobe_dotted() {
        for order in crate::sh::MIN_ORDER..=crate::sh::MAX_ORDER {
            let count = coefficient_count(order);
            // A light and a lobe with every coefficient in play, positive DC so that the
            // clamp at 0 rarely bites.
            let sh: [Vec<f32>; 3] = [0.3f32, 0.7, 1.1].map(|phase| {
                (0..count).map(|k| if k == 0 { 3.0 } else { 0.8 * (phase + 1.7 * k as f32).sin() }).collect()
            });
            let open: Vec<f64> = (0..order).map(|l| 2.0 / (1.0 + l as f64)).collect();
            let blocks = open_light_blocks(&sh, &open);
            let open_f32: Vec<f32> = open.iter().map(|&v| v as f32).collect();
            for i in 0..500 {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / 500.0;
                let phi = 2.399_963 * i as f64;
                let r = (1.0 - z * z).sqrt();
                let direction = [r * phi.cos(), r * phi.sin(), z];
                let expected = open_lit(order, &open_f32, direction, &sh);
                // SAFETY: the portable dots need no processor feature.
                let portable = unsafe { open_light::<PortableDots>(&blocks, order, direction) };
                let mut builds = vec![portable];
                #[cfg(target_arch = "x86_64")]
                if *crate::x86::AVX2_FMA {
                    // SAFETY: the processor has AVX2 and FMA.
                    builds.push(unsafe { open_light::<Avx2Dots>(&blocks, order, direction) });
                    // In lanes, this direction in lane `i % 8` among seven others.
                    let lanes = crate::shade::cap_packet::LANES;
                    let directions: [[f32; 3]; crate::shade::cap_packet::LANES] = std::array::from_fn(|lane| {
                        let (z, phi) = (0.9 - 0.25 * lane as f64, 1.1 * lane as f64);
                        let r = (1.0 - z * z).sqrt();
                        [r * phi.cos(), r * phi.sin(), z].map(|v| v as f32)
                    });
                    let mut directions = directions;
                    directions[i % lanes] = direction.map(|v| v as f32);
                    // SAFETY: the processor has AVX2 and FMA.
                    let lit = unsafe {
                        match order {
                            3 => open_lights_of_lanes::<3>(&blocks, &directions),
                            4 => open_lights_of_lanes::<4>(&blocks, &directions),
                            5 => open_lights_of_lanes::<5>(&blocks, &directions),
                            6 => open_lights_of_lanes::<6>(&blocks, &directions),
                            7 => open_lights_of_lanes::<7>(&blocks, &directions),
                            _ => open_lights_of_lanes::<8>(&blocks, &directions),
                        }
                    };
                    builds.push(lit[i % lanes]);
                }
                for got in builds {
                    for c in 0..3 {
                        assert!(
                            (got[c] - expected[c]).abs() < 1e-6 * expected[c].abs().max(1.0),
                            "order {order}, direction {direction:?}, channel {c}: {} against {}",
                            got[c],
                            expected[c]
                        );
                    }
                }
            }
        }
    }
}
