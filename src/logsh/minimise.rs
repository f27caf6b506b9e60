//! One-dimensional minimisation for the fitted tables: the Phong lobes' eps
//! ([`super::optimal_lobe_epsilon`]) and the caps' and bands' log depths
//! (`crate::shade::fitted_depth`).

/// What [`scan_then_golden`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScannedMinimum {
    /// The middle of the final golden-section bracket.
    pub refined: f64,
    /// The best point of the scan, and its error.
    pub best_scanned: (f64, f64),
}

/// Minimises `error` over `range`: a scan of `steps` equal steps (`steps + 1` points),
/// then `iterations` golden-section steps inside the scan's best point's neighbours
/// (the error need not be unimodal over the whole range). About
/// `steps + iterations + 3` evaluations.
pub fn scan_then_golden(
    error: impl Fn(f64) -> f64,
    range: (f64, f64),
    steps: usize,
    iterations: usize,
) -> ScannedMinimum {
    let (lo, hi) = range;
    let grid: Vec<f64> = (0..=steps).map(|k| lo + (hi - lo) * k as f64 / steps as f64).collect();
    let errors: Vec<f64> = grid.iter().map(|&x| error(x)).collect();
    let best = (0..=steps).min_by(|&a, &b| errors[a].total_cmp(&errors[b])).expect("non-empty grid");
    let (mut a, mut b) = (grid[best.saturating_sub(1)], grid[(best + 1).min(steps)]);
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (b - ratio * (b - a), a + ratio * (b - a));
    let (mut error_c, mut error_d) = (error(c), error(d));
    for _ in 0..iterations {
        if error_c < error_d {
            (b, d, error_d) = (d, c, error_c);
            c = b - ratio * (b - a);
            error_c = error(c);
        } else {
            (a, c, error_c) = (c, d, error_d);
            d = a + ratio * (b - a);
            error_d = error(d);
        }
    }
    ScannedMinimum { refined: 0.5 * (a + b), best_scanned: (grid[best], errors[best]) }
}
