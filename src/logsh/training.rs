//! Log vectors of the kind the tool sums per pixel, for fitting the OL table
//! ([`crate::sh::OlTable::fit`]).

use super::{cap_log_zh, lobe_log_zh, Lobe};
use crate::sh::basis::coefficient_count;
use crate::sh::rotation::add_rotated_zonal;

/// SplitMix64: a small deterministic generator, so the fitted table is the same on every
/// run and machine.
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    pub(crate) fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn unit_vector(&mut self) -> [f64; 3] {
        let z = 2.0 * self.next() - 1.0;
        let phi = 2.0 * std::f64::consts::PI * self.next();
        let s = (1.0 - z * z).sqrt();
        [s * phi.cos(), s * phi.sin(), z]
    }
}

/// `count` log vectors at `order`, each a sum of what one pixel sees: the hemisphere
/// behind a random tangent plane, zero to eight sphere caps (angular radius 3 to 80
/// degrees, in random directions, weighted by a ratio attenuation in [0.2, 1] a quarter
/// of the time) and, for three in four, a diffuse or Phong lobe (exponent 1 to 256) in a
/// random direction; one clamp `eps` per vector, drawn log-uniformly from [0.01, 0.5].
pub fn training_log_vectors(order: usize, count: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = SplitMix(seed);
    let mut zonal = vec![0.0; order];
    (0..count)
        .map(|_| {
            let mut acc = vec![0.0; coefficient_count(order)];
            let epsilon = (0.01f64.ln() + rng.next() * (0.5f64 / 0.01).ln()).exp();
            cap_log_zh(order, epsilon.ln(), std::f64::consts::FRAC_PI_2, &mut zonal);
            add_rotated_zonal(order, &zonal, 1.0, rng.unit_vector(), &mut acc);
            let caps = (rng.next() * 9.0) as usize;
            for _ in 0..caps {
                let alpha = (3.0 + 77.0 * rng.next()).to_radians();
                let weight = if rng.next() < 0.25 { 0.2 + 0.8 * rng.next() } else { 1.0 };
                cap_log_zh(order, epsilon.ln(), alpha, &mut zonal);
                add_rotated_zonal(order, &zonal, weight, rng.unit_vector(), &mut acc);
            }
            if rng.next() < 0.75 {
                let lobe = if rng.next() < 0.5 {
                    Lobe::Diffuse
                } else {
                    Lobe::Phong { exponent: (256f64.ln() * rng.next()).exp() }
                };
                let zh = lobe_log_zh(order, lobe, epsilon);
                add_rotated_zonal(order, &zh, 1.0, rng.unit_vector(), &mut acc);
            }
            acc
        })
        .collect()
}
