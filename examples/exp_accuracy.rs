//! Prints the relative L2 error of each SH exponentiation against exact quadrature, over
//! training-like log vectors scaled to several magnitudes, and HYB's error for several
//! scaling thresholds. `cargo run --release --example exp_accuracy`
use logsh::sh::exp::{exp_hyb_with, exp_series, ExactExp, OlTable};
use logsh::sh::*;

fn relative_l2(a: &[f64], b: &[f64]) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    (diff / b.iter().map(|y| y * y).sum::<f64>()).sqrt()
}

fn main() {
    for order in [3, 4, 6, 8] {
        let count = coefficient_count(order);
        let exact = ExactExp::new(order);
        let fine = ExactExp::with_grid(order, 12 * order + 48);
        let tensor = TriplingTensor::new(order);
        let ol = OlTable::fit(order, &logsh::logsh::training_log_vectors(order, 64, 1));
        let tests = logsh::logsh::training_log_vectors(order, 48, 99);
        for m in [0.25, 1.0, 2.0, 4.0, 8.0, 16.0] {
            let mut worst = [0.0f64; 7];
            for v in &tests {
                let mut f = v.clone();
                f[0] = 0.0;
                let norm = f.iter().map(|c| c * c).sum::<f64>().sqrt();
                f.iter_mut().for_each(|c| *c *= m / norm);
                let (mut reference, mut r2, mut out) = (vec![0.0; count], vec![0.0; count], vec![0.0; count]);
                fine.exp(&f, &mut reference);
                exact.exp(&f, &mut r2);
                worst[0] = worst[0].max(relative_l2(&r2, &reference));
                exp_series(&tensor, &f, &mut out);
                worst[1] = worst[1].max(relative_l2(&out, &reference));
                ol.exp(&f, &mut out);
                worst[2] = worst[2].max(relative_l2(&out, &reference));
                for (k, t) in [1.0, 0.5, 0.25, 0.125].iter().enumerate() {
                    exp_hyb_with(&tensor, &ol, *t, &f, &mut out);
                    worst[3 + k] = worst[3 + k].max(relative_l2(&out, &reference));
                }
            }
            let mut coarse = String::new();
            for nz in [order + 2, order + 4, 2 * order + 2, 2 * order + 6] {
                let grid = ExactExp::with_grid(order, nz);
                let mut w = 0.0f64;
                for v in &tests {
                    let mut f = v.clone();
                    f[0] = 0.0;
                    let norm = f.iter().map(|c| c * c).sum::<f64>().sqrt();
                    f.iter_mut().for_each(|c| *c *= m / norm);
                    let (mut reference, mut out) = (vec![0.0; count], vec![0.0; count]);
                    fine.exp(&f, &mut reference);
                    grid.exp(&f, &mut out);
                    w = w.max(relative_l2(&out, &reference));
                }
                coarse.push_str(&format!(" nz{nz} {w:.4}"));
            }
            println!("order {order} |f^| {m:5.2}:{coarse}");
            println!("order {order} |f^| {m:5.2}: grid {:.1e} series {:.4} OL {:.4} HYB(1) {:.4} HYB(.5) {:.4} HYB(.25) {:.4} HYB(.125) {:.4}", worst[0], worst[1], worst[2], worst[3], worst[4], worst[5], worst[6]);
        }
    }
}
