//! Supersampled frames resolved to the camera's resolution (`supersample` in scene.json):
//! every output the same linear filter of the samples, so that the compositing passes
//! still add up to the beauty and the edges of logsh's layers fall where a Cycles render
//! with the same pixel filter puts them.
//!
//! A frame with `n` samples per pixel along each axis has its sample `(i, j)` at
//! `((i + 0.5) / n, (j + 0.5) / n)` in output pixels. The filters:
//! - `box`: the mean of the pixel's own `n x n` samples (Cycles' Box filter of width 1 px);
//! - `blackman-harris`: Blender's default, width 1.5 px, the product of the 1-D window in
//!   x and in y (`filter_func_blackman_harris` in Cycles' `film.cpp`, which samples x and
//!   y independently from its table), over every sample within 0.75 px of the pixel's
//!   centre, neighbours' included, the weights renormalised (at the frame's edge too).
//!
//! Position and normal are data, which a filter would blend into points on no surface:
//! each output pixel takes those of its sample nearest the pixel's centre (sample
//! `(n / 2, n / 2)` of its block; for even `n`, the one below and right of the centre).

use super::compositing::ShadedPasses;
use std::f64::consts::PI;

/// The pixel filter of the resolve (`--pixel-filter`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum PixelFilter {
    /// The mean of the pixel's own samples: Cycles' Box filter, 1 px wide.
    #[default]
    Box,
    /// Blender's default: Blackman-Harris, 1.5 px wide.
    BlackmanHarris,
}

/// How a supersampled frame becomes the camera's pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Resolving {
    pub filter: PixelFilter,
    /// Shade every sample, not only where a pixel's samples differ
    /// ([`super::adaptive`]): what adaptive shading saves is measured against this.
    pub every_sample: bool,
}

/// Width of Blender's default Blackman-Harris pixel filter, in pixels.
pub const BLACKMAN_HARRIS_WIDTH: f64 = 1.5;

/// The Blackman-Harris window of `width` at offset `x` from its centre (0 beyond).
fn blackman_harris(x: f64, width: f64) -> f64 {
    if x.abs() >= 0.5 * width {
        return 0.0;
    }
    let v = 2.0 * PI * (x / width + 0.5);
    0.35875 - 0.48829 * v.cos() + 0.14128 * (2.0 * v).cos() - 0.01168 * (3.0 * v).cos()
}

/// The samples one output pixel reads along one axis, with their weights.
type Taps = Vec<(usize, f64)>;

/// The weights of a resolve, per axis (the filters are separable).
pub struct Resolve {
    pub samples: usize,
    pub width: usize,
    pub height: usize,
    columns: Vec<Taps>,
    rows: Vec<Taps>,
}

impl Resolve {
    /// The resolve of a `width * samples` x `height * samples` frame to `width` x `height`.
    pub fn new(samples: usize, width: usize, height: usize, filter: PixelFilter) -> Self {
        let axis = |pixels: usize| -> Vec<Taps> {
            (0..pixels)
                .map(|p| {
                    let taps: Taps = match filter {
                        PixelFilter::Box => (p * samples..(p + 1) * samples).map(|s| (s, 1.0)).collect(),
                        PixelFilter::BlackmanHarris => {
                            let centre = p as f64 + 0.5;
                            let reach = (0.5 * BLACKMAN_HARRIS_WIDTH * samples as f64).ceil() as usize + 1;
                            let first = (p * samples).saturating_sub(reach);
                            let last = ((p + 1) * samples + reach).min(pixels * samples);
                            (first..last)
                                .map(|s| {
                                    (
                                        s,
                                        blackman_harris(
                                            (s as f64 + 0.5) / samples as f64 - centre,
                                            BLACKMAN_HARRIS_WIDTH,
                                        ),
                                    )
                                })
                                .filter(|(_, w)| *w > 0.0)
                                .collect()
                        }
                    };
                    let total: f64 = taps.iter().map(|(_, w)| w).sum();
                    taps.into_iter().map(|(s, w)| (s, w / total)).collect()
                })
                .collect()
        };
        Self { samples, width, height, columns: axis(width), rows: axis(height) }
    }

    /// `values` (the supersampled frame, row-major from the top row) filtered to the
    /// output resolution.
    pub fn filter<const K: usize>(&self, values: &[[f32; K]]) -> Vec<[f32; K]> {
        let sampled_width = self.width * self.samples;
        let mut out = Vec::with_capacity(self.width * self.height);
        for rows in &self.rows {
            for columns in &self.columns {
                let mut sum = [0.0f64; K];
                for &(row, wy) in rows {
                    for &(column, wx) in columns {
                        let v = values[row * sampled_width + column];
                        for k in 0..K {
                            sum[k] += wx * wy * f64::from(v[k]);
                        }
                    }
                }
                out.push(sum.map(|s| s as f32));
            }
        }
        out
    }

    /// A scalar channel filtered as [`Self::filter`] does.
    pub fn filter_scalar(&self, values: &[f32]) -> Vec<f32> {
        let as_arrays: Vec<[f32; 1]> = values.iter().map(|&v| [v]).collect();
        self.filter(&as_arrays).into_iter().map(|[v]| v).collect()
    }

    /// Each output pixel's sample nearest its centre (module doc).
    pub fn nearest<T: Copy>(&self, values: &[T]) -> Vec<T> {
        let (n, sampled_width) = (self.samples, self.width * self.samples);
        let mut out = Vec::with_capacity(self.width * self.height);
        for y in 0..self.height {
            for x in 0..self.width {
                out.push(values[(y * n + n / 2) * sampled_width + x * n + n / 2]);
            }
        }
        out
    }

    /// Every pass of `passes` at the output resolution: colours and visibility terms
    /// filtered, position and normal taken from the nearest sample.
    pub fn passes(&self, passes: &ShadedPasses) -> ShadedPasses {
        ShadedPasses {
            width: self.width,
            height: self.height,
            beauty: self.filter(&passes.beauty),
            diffuse: self.filter(&passes.diffuse),
            specular: self.filter(&passes.specular),
            environment: self.filter(&passes.environment),
            indirect: self.filter(&passes.indirect),
            indirect_heightfield: self.filter(&passes.indirect_heightfield),
            indirect_blockers: self.filter(&passes.indirect_blockers),
            visibility: self.filter_scalar(&passes.visibility),
            visibility_heightfield: self.filter_scalar(&passes.visibility_heightfield),
            visibility_blockers: self.filter_scalar(&passes.visibility_blockers),
            position: self.nearest(&passes.position).into(),
            normal: self.nearest(&passes.normal).into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both filters keep a constant image constant (weights renormalised, the frame's edges
    /// included), and the box filter averages exactly the pixel's own samples.
    #[test]
    fn filters_keep_constants_and_boxes_average() {
        for filter in [PixelFilter::Box, PixelFilter::BlackmanHarris] {
            for n in 1..=4 {
                let resolve = Resolve::new(n, 5, 3, filter);
                let constant = vec![[0.25f32, 2.0]; 5 * n * 3 * n];
                for v in resolve.filter(&constant) {
                    assert!((v[0] - 0.25).abs() < 1e-6 && (v[1] - 2.0).abs() < 1e-6, "{filter:?} n {n}: {v:?}");
                }
            }
        }
        let resolve = Resolve::new(2, 2, 1, PixelFilter::Box);
        let values: Vec<[f32; 1]> = [1.0, 2.0, 10.0, 20.0, 3.0, 4.0, 30.0, 40.0].map(|v| [v]).to_vec();
        assert_eq!(resolve.filter(&values), vec![[2.5], [25.0]]);
        assert_eq!(resolve.nearest(&[0, 1, 2, 3, 4, 5, 6, 7]), vec![5, 7]);
    }

    /// Blackman-Harris 1.5 px: one bright sample spreads into the neighbouring pixels, and
    /// its window matches Cycles' at the centre (1) and the edge (0).
    #[test]
    fn blackman_harris_reaches_the_neighbours() {
        assert!((blackman_harris(0.0, 1.5) - 1.0).abs() < 1e-4);
        assert!(blackman_harris(0.75, 1.5).abs() < 1e-12 && blackman_harris(0.7, 1.5) > 0.0);
        // With 4 samples per pixel, the last sample of the first pixel (0.875 px) lies
        // 0.625 px from the second pixel's centre: inside the window's 0.75.
        let resolve = Resolve::new(4, 3, 1, PixelFilter::BlackmanHarris);
        let mut values = vec![[0.0f32]; 12 * 4];
        values[3] = [1.0];
        let out = resolve.filter(&values);
        assert!(out[1][0] > 0.0 && out[0][0] > out[1][0] && out[2][0] == 0.0, "{out:?}");
    }
}
