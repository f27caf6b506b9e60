//! How eps trades off per lobe and order: the L2 error between the order-n SH projection
//! of a BRDF lobe and the exact exponential of its log-SH lobe, over eps, for the paper's
//! absolute clamp `log(max(f, eps))` and this tool's peak-relative clamp
//! `log(max(f / f_max, eps)) + log(f_max)`. Reproduces paper 000's Figure 6 (order 4, Phong
//! r = 1 to 5, absolute clamp) and tabulates the L2-optimal eps per lobe and order.
//!
//! `cargo run --release --example epsilon_study -- docs/epsilon` writes `lobe_l2.csv`,
//! `optimal.csv`, `figure6_paper_clamp.svg` and `figure6_peak_relative.svg` there.
use logsh::logsh::{lobe_exp_error, optimal_lobe_epsilon, Lobe};
use logsh::plot::{Chart, Scale, Series};
use logsh::sh::basis::legendre;
use logsh::sh::quadrature::gauss_legendre_on;
use logsh::sh::{index, rotate_zonal, ExactExp};
use std::f64::consts::PI;
use std::io::Write;

/// ZH coefficients of `h(cos theta)`, integrating piecewise on `breaks` (kinks) with
/// geometric refinement towards `z = 0+` where `log z` lives. Exact to about 1e-12.
fn zonal_projection(order: usize, breaks: &[f64], h: impl Fn(f64) -> f64) -> Vec<f64> {
    let mut cuts = vec![-1.0, 0.0, 1.0];
    cuts.extend(breaks.iter().copied().filter(|b| *b > -1.0 && *b < 1.0));
    let mut z = 1e-12;
    while z < 1.0 {
        cuts.push(z);
        z *= 4.0;
    }
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let mut p = vec![0.0; order];
    let mut out = vec![0.0; order];
    for pair in cuts.windows(2) {
        for (z, w) in gauss_legendre_on(24, pair[0], pair[1]) {
            legendre(order, z, &mut p);
            for l in 0..order {
                out[l] += 2.0 * PI * ((2 * l + 1) as f64 / (4.0 * PI)).sqrt() * w * h(z) * p[l];
            }
        }
    }
    out
}

#[derive(Clone, Copy, PartialEq)]
enum Clamp {
    Paper,
    PeakRelative,
}

fn lobe_error(order: usize, lobe: Lobe, epsilon: f64, clamp: Clamp, exact: &ExactExp) -> f64 {
    let (r, peak) = match lobe {
        Lobe::Diffuse => (1.0, 1.0 / PI),
        Lobe::Phong { exponent } => (exponent, (exponent + 1.0) / (2.0 * PI)),
    };
    let truth = zonal_projection(order, &[], |z| lobe.value(z));
    if clamp == Clamp::PeakRelative {
        return lobe_exp_error(order, lobe, epsilon, exact);
    }
    let log_zh = match clamp {
        Clamp::PeakRelative => unreachable!("handled by the library"),
        Clamp::Paper => {
            let kink = if epsilon < peak { (epsilon / peak).powf(1.0 / r) } else { 1.0 };
            zonal_projection(order, &[kink], |z| lobe.value(z).max(epsilon).ln())
        }
    };
    let mut f = vec![0.0; order * order];
    rotate_zonal(order, &log_zh, [0.0, 0.0, 1.0], &mut f);
    let mut e = vec![0.0; order * order];
    exact.exp(&f, &mut e);
    (0..order).map(|l| (e[index(l, 0)] - truth[l]).powi(2)).sum::<f64>().sqrt()
}

fn main() -> std::io::Result<()> {
    let out = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "docs/epsilon".into()));
    std::fs::create_dir_all(&out)?;
    let epsilons: Vec<f64> = (0..=40).map(|k| 10f64.powf(-3.0 + 3.0 * k as f64 / 40.0)).filter(|e| *e < 0.95).collect();
    let lobes: Vec<(String, Lobe)> = std::iter::once(("diffuse".to_string(), Lobe::Diffuse))
        .chain(
            [1.0, 2.0, 3.0, 4.0, 5.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0, 1024.0]
                .map(|r| (format!("phong{r}"), Lobe::Phong { exponent: r })),
        )
        .collect();
    let mut csv = std::fs::File::create(out.join("lobe_l2.csv"))?;
    let mut optimal = std::fs::File::create(out.join("optimal.csv"))?;
    writeln!(csv, "order,lobe,clamp,epsilon,l2_error")?;
    writeln!(optimal, "order,lobe,clamp,best_epsilon_on_grid,l2_error_at_best,l2_error_at_default_epsilon,tool_epsilon,l2_error_at_tool_epsilon")?;
    let mut figure6 = [Vec::new(), Vec::new()];
    for order in 3..=8 {
        let exact = ExactExp::new(order);
        for (name, lobe) in &lobes {
            for (c, clamp) in [Clamp::Paper, Clamp::PeakRelative].into_iter().enumerate() {
                let clamp_name = if clamp == Clamp::Paper { "paper" } else { "peak_relative" };
                let errors: Vec<f64> = epsilons.iter().map(|&e| lobe_error(order, *lobe, e, clamp, &exact)).collect();
                for (e, err) in epsilons.iter().zip(&errors) {
                    writeln!(csv, "{order},{name},{clamp_name},{e:.6},{err:.6}")?;
                }
                let (best, best_err) = epsilons
                    .iter()
                    .zip(&errors)
                    .min_by(|a, b| a.1.total_cmp(b.1))
                    .map(|(e, r)| (*e, *r))
                    .expect("grid");
                let default = lobe_error(order, *lobe, logsh::shade::default_epsilon(order), clamp, &exact);
                // What `logsh shade` uses: the whole-pixel default for the diffuse lobe, the
                // L2-optimal eps for Phong lobes.
                let tool = match lobe {
                    Lobe::Diffuse => logsh::shade::default_epsilon(order),
                    Lobe::Phong { .. } => optimal_lobe_epsilon(order, *lobe, &exact),
                };
                let tool_err = lobe_error(order, *lobe, tool, clamp, &exact);
                writeln!(
                    optimal,
                    "{order},{name},{clamp_name},{best:.4},{best_err:.6},{default:.6},{tool:.4},{tool_err:.6}"
                )?;
                if order == 4 {
                    if let Lobe::Phong { exponent } = lobe {
                        if *exponent <= 5.0 {
                            figure6[c].push(Series {
                                name: format!("r = {exponent}"),
                                points: epsilons.iter().copied().zip(errors.iter().copied()).collect(),
                                line: true,
                                labels: vec![],
                            });
                        }
                    }
                }
            }
        }
    }
    for (series, (file, clamp)) in figure6.into_iter().zip([
        ("figure6_paper_clamp.svg", "log(max(f, eps)) (the paper's clamp)"),
        ("figure6_peak_relative.svg", "log(max(f/f_max, eps)) + log(f_max)"),
    ]) {
        let chart = Chart {
            title: format!("Order 4 Phong lobes: L2 error of exp(log-SH lobe) vs SH lobe, clamp {clamp}"),
            x_label: "eps".into(),
            y_label: "L2 error of the ZH vector".into(),
            x_scale: Scale::Log,
            y_scale: Scale::Log,
            series,
        };
        std::fs::write(out.join(file), chart.to_svg())?;
    }
    eprintln!("wrote {}", out.display());
    Ok(())
}
