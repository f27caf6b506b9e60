//! Typical non-DC magnitudes |f^| of the log vectors a pixel exponentiates: an unoccluded
//! receiver (diffuse lobe + tangent hemisphere) per order and eps, and the same under one
//! sphere cap of 30 degrees. `cargo run --release --example log_magnitudes`
use logsh::logsh::{cap_log_zh, lobe_log_zh, Lobe};
use logsh::sh::add_rotated_zonal;

fn main() {
    for order in [3, 4, 8] {
        for eps in [1e-6, 1e-3, 0.05, 0.1, 0.15, 0.9] {
            let mut f = vec![0.0; order * order];
            add_rotated_zonal(order, &lobe_log_zh(order, Lobe::Diffuse, eps), 1.0, [0.0, 0.0, 1.0], &mut f);
            let mut cap = vec![0.0; order];
            cap_log_zh(order, f64::ln(eps), std::f64::consts::FRAC_PI_2, &mut cap);
            add_rotated_zonal(order, &cap, 1.0, [0.0, 0.0, -1.0], &mut f);
            let open = f[1..].iter().map(|c| c * c).sum::<f64>().sqrt();
            cap_log_zh(order, f64::ln(eps), 30f64.to_radians(), &mut cap);
            add_rotated_zonal(order, &cap, 1.0, [0.5, 0.0, 0.866], &mut f);
            let shadowed = f[1..].iter().map(|c| c * c).sum::<f64>().sqrt();
            println!("order {order} eps {eps:<6}: |f^| unoccluded {open:6.2}, one 30-degree cap {shadowed:6.2}");
        }
    }
}
