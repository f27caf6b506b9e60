//! `exp*`, the SH exponentiation of a log vector (paper 000, Section 5), with the tables
//! its method needs, and the hand-over of the SH-space methods to the quadrature beyond
//! the magnitudes where they hold.

use crate::memo::Memo;
use crate::sh::exp::{exp_hyb_with, exp_series, ExactExp, OlTable};
use crate::sh::{ExpMethod, Real, TriplingTensor, MAX_COEFFICIENTS};
use std::sync::Arc;

/// Largest non-DC magnitude `|f^|` given to the SH-space methods; a pixel beyond it is
/// exponentiated by `quad` instead, which the lobe's peak bounds. Pixels at the default
/// eps carry 5 to 9 (`examples/log_magnitudes.rs`); eps below about 0.01 or hundreds of
/// overlapping caps go far beyond, where the methods run away (`tests/extremes.rs`):
/// OL's coefficients grow like `exp(|f^|)` (an albedo-1 receiver came out 17 at
/// `|f^| < 16`, hence its lower limit), HYB's squarings amplify its start 2^p-fold until
/// f32 overflows, and the series needs more than 64 terms.
pub fn sh_space_max_magnitude(method: ExpMethod) -> f64 {
    match method {
        ExpMethod::Ol => 8.0,
        _ => 16.0,
    }
}

/// `exp*` with the tables its method needs, built once per order and method in a process.
pub struct Exponentiator {
    pub(crate) method: ExpMethod,
    /// The fine grid for `exact`; the coarse one for `quad`, and for the other methods'
    /// fallback beyond [`sh_space_max_magnitude`].
    pub(crate) exact: Option<Arc<ExactExp>>,
    pub(crate) tensor: Option<Arc<TriplingTensor>>,
    pub(crate) ol: Option<Arc<OlTable>>,
    pub(crate) hyb_threshold: f64,
}

/// Training vectors for the OL fit: 64 of them, a fixed seed (the table is the same on
/// every run). The fit runs once per order in a process; 256 vectors made `ol` slower per
/// frame than `quad`.
const OL_TRAINING_COUNT: usize = 64;
const OL_TRAINING_SEED: u64 = 0x1065_5a11;

impl Exponentiator {
    pub fn new(order: usize, method: ExpMethod, hyb_threshold: f64) -> Self {
        let needs_tensor = matches!(method, ExpMethod::Series | ExpMethod::Hyb);
        let needs_ol = matches!(method, ExpMethod::Ol | ExpMethod::Hyb);
        Self {
            method,
            exact: Some(ExactExp::shared(order, method == ExpMethod::Exact)),
            tensor: needs_tensor.then(|| TriplingTensor::shared(order)),
            ol: needs_ol.then(|| {
                static FITS: Memo<usize, OlTable> = Memo::new();
                FITS.get_or_build(order, || {
                    OlTable::fit(order, &crate::logsh::training_log_vectors(order, OL_TRAINING_COUNT, OL_TRAINING_SEED))
                })
            }),
            hyb_threshold,
        }
    }

    pub fn method(&self) -> ExpMethod {
        self.method
    }

    /// `out = exp*(f)` for a log function known never to exceed `ceiling` (the log of the
    /// lobe's peak); the quadrature methods clamp their nodes there
    /// ([`ExactExp::exp_below`]), the SH-space ones cannot.
    ///
    /// With `floored = Some((v, floor))`, the quadrature floors the part `v` of `f` at
    /// `floor` at every node ([`ExactExp::exp_floored`]); the SH-space methods cannot, and
    /// leave it as it is.
    pub fn exp<T: Real>(&self, f: &[T], floored: Option<(&[T], f64)>, ceiling: f64, out: &mut [T]) {
        let quadrature = self.exact.as_ref().expect("always built");
        let count = f.len();
        match self.method {
            ExpMethod::Exact | ExpMethod::Quad => quadrature.exp_floored(f, floored, ceiling, out),
            method => {
                let magnitude =
                    f[1..].iter().fold(0.0f64, |acc, c| acc + c.to_f64().unwrap_or(f64::INFINITY).powi(2)).sqrt();
                let weight = quadrature_weight(method, magnitude);
                if weight >= 1.0 {
                    return quadrature.exp_floored(f, floored, ceiling, out);
                }
                self.exp_sh_space(f, out);
                if weight > 0.0 {
                    let mut quad = [T::zero(); MAX_COEFFICIENTS];
                    quadrature.exp_floored(f, floored, ceiling, &mut quad[..count]);
                    let w = T::of(weight);
                    for (o, q) in out[..count].iter_mut().zip(&quad[..count]) {
                        *o = *o + w * (*q - *o);
                    }
                }
            }
        }
    }

    /// The first coefficient of [`Self::exp`] (f64), computed alone where the method is the
    /// quadrature's.
    pub fn exp_first(&self, f: &[f64], floored: Option<(&[f64], f64)>, ceiling: f64) -> f64 {
        match self.method {
            ExpMethod::Exact | ExpMethod::Quad => {
                self.exact.as_ref().expect("always built").exp_floored_first(f, floored, ceiling)
            }
            _ => {
                let mut out = [0.0; MAX_COEFFICIENTS];
                self.exp(f, floored, ceiling, &mut out[..f.len()]);
                out[0]
            }
        }
    }

    fn exp_sh_space<T: Real>(&self, f: &[T], out: &mut [T]) {
        match self.method {
            ExpMethod::Series => exp_series(self.tensor.as_ref().expect("built with its table"), f, out),
            ExpMethod::Ol => self.ol.as_ref().expect("built with its table").exp(f, out),
            ExpMethod::Hyb => exp_hyb_with(
                self.tensor.as_ref().expect("built with its table"),
                self.ol.as_ref().expect("built with its table"),
                self.hyb_threshold,
                f,
                out,
            ),
            ExpMethod::Exact | ExpMethod::Quad => unreachable!("quadrature methods are not SH-space"),
        }
    }
}

/// Width of the band of magnitudes below [`sh_space_max_magnitude`] over which an
/// SH-space method hands over to `quad`: the result is blended linearly across it, so
/// the hand-over leaves no seam in the image, and two executors whose magnitudes differ
/// by rounding give nearly the same value (a hard switch made a 0.06 jump on the `cones`
/// sample at `--quality draft`).
pub const SH_SPACE_BLEND: f64 = 1.0;

/// How much of `quad` a pixel of magnitude `|f^|` takes with an SH-space `method`: 0 up to
/// the blend band, 1 from [`sh_space_max_magnitude`] on (and for a non-finite magnitude).
pub fn quadrature_weight(method: ExpMethod, magnitude: f64) -> f64 {
    let max = sh_space_max_magnitude(method);
    if !(magnitude <= max) {
        return 1.0;
    }
    ((magnitude - (max - SH_SPACE_BLEND)) / SH_SPACE_BLEND).clamp(0.0, 1.0)
}
