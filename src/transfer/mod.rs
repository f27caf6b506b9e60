//! Transfer layers (`logsh render --transfer`) and relighting from them (`logsh relight`,
//! `logsh view`).
//!
//! Per pixel, logsh's environment term is `max(exp*(V + lobe) . L, 0)`: the exponentiated
//! log visibility plus BRDF lobe (paper 000, Eq. 9) dotted with the light's SH vector.
//! The first factor does not depend on the light, so written out it relights the pixel
//! under any other light, with the shadows that light casts through the same
//! visibility. [`relight`] recomputes the beauty and every compositing pass of
//! [`crate::render`] that way.
//!
//! # Layers (added to the frame's EXR; "colour" is `--colour-type`, half by default)
//!
//! | channels | type | what |
//! |---|---|---|
//! | `sh_diffuse_<k>.{R,G,B,A}` | colour | `exp*(V + D)`, coefficients `k..k+3` (the last block may be shorter) |
//! | `sh_unoccluded_<k>.*` | colour | `exp*(T + D)`: the visibility passes' denominator |
//! | `sh_heightfield_<k>.*`, `sh_blockers_<k>.*` | colour | their numerators; only in frames with both |
//! | `sh_specular_<k>.*` | colour | the glossy transfer (below); only in scenes with a Phong material |
//! | `albedo.{R,G,B}`, `specular_colour.{R,G,B}` | colour | the material's colours, times the pixel's tint (water's, or the G-buffer's Diffuse and Glossy Color passes) |
//! | `lamps_diffuse.{R,G,B}`, `lamps_specular.{R,G,B}` | colour | the scene's Sun and point lamps, shaded (kept by a relight, but for the Sun lamps when it turns them) |
//! | `sun_lamps_diffuse.{R,G,B}`, `sun_lamps_specular.{R,G,B}` | colour | the Sun lamps' part of `lamps_*`; only in frames with a Sun lamp |
//! | `glossy_lobe.V` | float | what the glossy term reads: 0 nothing, 1 the light itself (mirror, background), 2 `sh_specular`, `3 + j` the header's prefiltered lobe `j` |
//! | `glossy_direction.{X,Y,Z}` | float | the direction it reads along: the mirrored view, or the camera ray |
//! | `glossy_weight.{X,Y}` | colour | prefiltered lobes: `A share cone` and `A (1 - share)` |
//! | `diffuse_normal.{X,Y,Z}` | float | the normal the diffuse light is corrected at (the surface's, or under water the reflected surface's); only in frames whose header records `open_diffuse` |
//! | `horizon.0` to `horizon.<S-1>` | half | the height field's highest horizon tangent over each of `S` sectors of the W azimuths `2 pi k / W` (`k S / W` the sector; `S = min(16, W)`, each azimuth's own by default, recorded in the header; 4 or 8 in files that do not record it, as many as they hold), rounded up, infinite where none was marched ([`crate::heightfield::HorizonPyramid::sector_maxima`]); only in frames whose height field may shadow a Sun lamp, or a sun the render took out of its map, at some turn ([`crate::heightfield::HorizonPyramid::may_rise_at_any_azimuth`]) |
//!
//! `D` is the diffuse lobe about the normal, `V` the log visibility, `T` the tangent and
//! ground planes alone. Relit, per pixel and colour channel, with `L` the light's SH vector:
//!
//! ```text
//! diffuse   = albedo C(max(sh_diffuse . L, 0)) + lamps_diffuse
//! specular  = specular_colour G + lamps_specular            (alpha 1)
//! environment = specular_colour G                            (alpha 0, the background)
//! G = max(sh_specular . L, 0)                         lobe 2
//!   = P_j(R) (X + Y ratio)                            lobe 3 + j, R = glossy_direction
//!   = light(R)                                        lobe 1
//! ratio = lum(max(sh_specular . L, 0)) / lum(max(open_j(R) . L, 0)), clamped to [0, 1]
//! visibility_x = lum(max(sh_x . L, 0)) / lum(max(sh_unoccluded . L, 0))
//! C(d) = E(n) / pi clamp(d / max(open(n) . L, 0), 0, 1)  n = diffuse_normal, per channel
//! ```
//!
//! with `P_j` the light prefiltered with lobe `j` and `open_j` its exponentiated lobe
//! (both as [`crate::shade::glossy`] builds them; the header lists the lobes). `C` is the
//! render's correction of the diffuse light to the map's irradiance `E` (its order-8
//! projection), `open` the header's `open_diffuse` ZH turned to `n`
//! ([`crate::shade::kernel::open_corrected_channel`]); where the header records no
//! `open_diffuse` (a light without a map), or `open(n) . L` is dark, `C(d) = d`.
//!
//! # Header (`logshTransfer`, a JSON text attribute of the part)
//!
//! The SH convention (order, basis, normalisation, axes, coefficient index), the light the
//! frame was shaded with (map file, strength, Mapping rotation, turn), the window, whether
//! the ground plane hides the lower hemisphere, the prefiltered lobes, the scene's Sun
//! lamps as rendered (azimuth and elevation), the render's `--light-rotation` and its
//! shading settings, checksums of what the Sun lamps were shaded from, the `horizon`
//! layer's sectors, and the open receiver's diffuse ZH where the diffuse light is
//! corrected.
//!
//! # Size
//!
//! Per pixel at order `n`, in half floats: `n^2` per transfer layer (diffuse, unoccluded,
//! specular with a Phong material, heightfield and blockers with both occluders), 14
//! colour values and 4 floats, 3 floats more under a map (`diffuse_normal`), and 6
//! colour values more with a Sun lamp, with 16 halves more where a height field may
//! shadow it at some turn. At order 4 with everything but a Sun lamp, under a map,
//! `5 x 16 x 2 + 14 x 2 + 7 x 4 = 216` bytes, 112 MB uncompressed at 960 x 540 before
//! ZIP; a diffuse scene of spheres only, `2 x 16 x 2 + 56 = 120` bytes.
//!
//! # What a relight shades again
//!
//! The transfer holds the environment in SH: a relight with `--sharp-lights off` equals a
//! shade with it. Suns that a render takes out of the map (`--sharp-lights auto`, the
//! default) no layer holds: a default relight takes them out of its light with the
//! render's decomposition, holds the residual in SH, and shades them again from the scene
//! ([`RelightLight::with_sharp_suns`], [`SunLampTurn::shade_again`]), as the render does
//! (4e-5 from the default render on the sunny dunes of docs/performance-log.md); held in SH they come back
//! with the soft shadows SH gives them (0.054 there). The scene's own point lamps stay as
//! they were rendered (`lamps_*`), as `--light-rotation` leaves them. A render's `--light-rotation` turns Sun lamps with the map; a
//! relight does too by shading them again from the scene ([`SunLampTurn`], about a Sun
//! lamp's share of a render; the `horizon` layer answers most pixels' horizons along the
//! turned lamps without a march, [`crate::heightfield::HorizonsBetween`]), or keeps them
//! as rendered (`--sun-lamps keep`: on a scene with a 2 deg Sun lamp, 0.050 from the
//! turned render, docs/performance-log.md).

mod layers;
mod relight;
mod shade;
mod sun_lamps;

pub use layers::{
    holds_transfer, PixelTransfer, PrefilteredLobe, ShConvention, TransferFrame, TransferHeader, TRANSFER_ATTRIBUTE,
};
#[cfg(test)]
pub(crate) use relight::relit_dunes;
pub use relight::{relight, relight_reusing, RelightLight, RelightOptions, SampledMap, SAMPLED_MAP_WIDTH};
pub use shade::{check_grid, shade_with_transfer};
pub use sun_lamps::{
    describe_sun_lamps, offering_soft_suns, offering_to_keep, GBufferDigest, SunLampFrame, SunLampInputs, SunLampTurn,
};

/// `glossy_lobe` codes (module doc).
pub mod lobe_code {
    pub const NONE: f32 = 0.0;
    pub const MIRROR: f32 = 1.0;
    pub const SH: f32 = 2.0;
    /// The first prefiltered lobe; lobe `j` is `PREFILTERED + j`.
    pub const PREFILTERED: f32 = 3.0;
}
