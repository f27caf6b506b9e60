//! Unoccluded diffuse plane under a constant white sky, with and without the ground's
//! lower-hemisphere log visibility in the sum, exact exponentiation, per order and eps.
//! `cargo run --release --example unoccluded`
use logsh::logsh::*;
use logsh::sh::*;
fn main() {
    for order in 3..=8 {
        for eps in [0.02, 0.05, 0.1, 0.2] {
            let zh = lobe_log_zh(order, Lobe::Diffuse, eps);
            let mut f = vec![0.0; order * order];
            rotate_zonal(order, &zh, [0.0, 0.0, 1.0], &mut f);
            let mut e = vec![0.0; order * order];
            let exact = ExactExp::new(order);
            exact.exp(&f, &mut e);
            let alone = e[0] * logsh::sh::exp::ONE_DC;
            let mut slice = vec![0.0; order];
            nlp_slice(order, eps.ln(), 0.0, &mut slice);
            for l in 0..order {
                f[index(l, 0)] += (2.0 * std::f64::consts::PI).sqrt() * slice[l];
            }
            exact.exp(&f, &mut e);
            let ground = e[0] * logsh::sh::exp::ONE_DC;
            println!("order {order} eps {eps}: lobe alone {alone:.4}, with ground {ground:.4}");
        }
    }
}
