//! CPU kernel costs: each SH exponentiation on a typical per-pixel log vector, the
//! per-pixel blocker accumulation, the height-field march and the glossy lobes'
//! prefiltered maps. Compare methods as ratios
//! within one run: `cargo bench --bench kernels`.
use criterion::{criterion_group, criterion_main, Criterion};
use logsh::logsh::training_log_vectors;
use logsh::sh::{ExpMethod, MAX_COEFFICIENTS};
use logsh::shade::Exponentiator;
use std::hint::black_box;

fn exponentiation(c: &mut Criterion) {
    for order in [3, 4, 6, 8] {
        let count = order * order;
        // Training vectors are sums of what pixels see: a tangent hemisphere, caps and a lobe.
        let vectors: Vec<Vec<f32>> = training_log_vectors(order, 16, 42)
            .into_iter()
            .map(|v| v.into_iter().map(|c| c as f32).collect())
            .collect();
        for method in [ExpMethod::Ol, ExpMethod::Hyb, ExpMethod::Series, ExpMethod::Quad, ExpMethod::Exact] {
            let exp = Exponentiator::new(order, method, logsh::sh::exp::HYB_MAGNITUDE);
            let mut out = [0.0f32; MAX_COEFFICIENTS];
            c.bench_function(&format!("exp/{method:?}/order{order}"), |b| {
                b.iter(|| {
                    for v in &vectors {
                        exp.exp(black_box(&v[..count]), None, logsh::sh::exp::MAX_LOG_VALUE, &mut out[..count]);
                    }
                })
            });
        }
    }
}

/// A pixel's `exp*(f) . L` at the `quad` grid: exponentiated, projected back to SH and
/// dotted with the light in f64 (`ExactExp::exp_floored`, the oracle), against the light
/// folded into the quadrature in f32 (`FoldedQuadrature::lit`, the CPU executor's path).
fn lighting(c: &mut Criterion) {
    use logsh::sh::{ExactExp, FoldedQuadrature};
    for order in [4, 8] {
        let count = order * order;
        let vectors = training_log_vectors(order, 16, 42);
        let vectors32: Vec<Vec<f32>> = vectors.iter().map(|v| v.iter().map(|&c| c as f32).collect()).collect();
        let light: [Vec<f64>; 3] = std::array::from_fn(|c| (0..count).map(|k| 1.0 / (1.0 + (k + c) as f64)).collect());
        let quadrature = ExactExp::fast(order);
        let folded = FoldedQuadrature::new(&quadrature, &light);
        c.bench_function(&format!("lit/projected f64/order{order}"), |b| {
            b.iter(|| {
                let mut out = [0.0f64; MAX_COEFFICIENTS];
                let mut sum = [0.0f64; 3];
                for v in &vectors {
                    quadrature.exp_floored(black_box(&v[..count]), Some((&v[..count], -2.3)), 1.0, &mut out[..count]);
                    for (s, l) in sum.iter_mut().zip(&light) {
                        *s += l.iter().zip(&out[..count]).map(|(a, b)| a * b).sum::<f64>();
                    }
                }
                black_box(sum)
            })
        });
        c.bench_function(&format!("lit/folded f32/order{order}"), |b| {
            b.iter(|| {
                let mut sum = [0.0f32; 3];
                for v in &vectors32 {
                    let lit = folded.lit(black_box(&v[..count]), Some((&v[..count], -2.3)), 1.0);
                    for (s, l) in sum.iter_mut().zip(lit) {
                        *s += l;
                    }
                }
                black_box(sum)
            })
        });
    }
}

fn blockers(c: &mut Criterion) {
    use logsh::logsh::{cap_log_zh, view_blocker, BlockerView};
    use logsh::sh::add_rotated_zonal;
    for order in [4, 8] {
        let spheres: Vec<([f32; 3], f32)> =
            (0..50).map(|i| ([i as f32 * 0.3 - 7.0, (i % 7) as f32, 2.0 + (i % 3) as f32], 0.5)).collect();
        c.bench_function(&format!("blockers50/order{order}"), |b| {
            b.iter(|| {
                let mut acc = [0.0f32; MAX_COEFFICIENTS];
                let mut zonal = [0.0f32; 8];
                for (centre, radius) in &spheres {
                    if let BlockerView::Cap { direction, alpha, weight } =
                        view_blocker([0.0; 3], [0.0, 0.0, 1.0], *centre, *radius, false)
                    {
                        cap_log_zh(order, 0.1f32.ln(), alpha, &mut zonal[..order]);
                        add_rotated_zonal(order, &zonal[..order], weight, direction, &mut acc[..order * order]);
                    }
                }
                black_box(acc)
            })
        });
    }
}

/// The sphere caps of 64 receivers on a floor facing a wall of 400 spheres (the
/// `wrecking_ball` sample's shape), clustered at the default ratio: each receiver walking
/// the tree and adding its caps one by one in f32 (the kernel's scalar path), against
/// packets of eight receivers sharing one walk ([`logsh::shade::cap_packet`]).
fn blocker_packets(c: &mut Criterion) {
    use logsh::logsh::{cap_log_zh, view_blocker, BlockerView};
    use logsh::scene::Sphere;
    use logsh::sh::add_rotated_zonal;
    use logsh::shade::blocker_tree::BlockerTree;
    use logsh::shade::cap_packet::{CapPacket, Receiver, LANES};
    use logsh::shade::fitted_depth::{depth_at, overlapped_depth, DEPTH_INTERVALS};
    const LOG_EPSILON: f32 = -std::f32::consts::LN_10;
    let spheres: Vec<Sphere> = (0..400)
        .map(|i| {
            Sphere::new(
                [(i % 40) as f64 * 0.25 - 5.0, 3.0 + (i / 200) as f64 * 0.25, 0.125 + ((i / 40) % 5) as f64 * 0.25],
                0.15,
            )
        })
        .collect();
    let tree = BlockerTree::new(&spheres, logsh::shade::settings::DEFAULT_CLUSTER_RATIO);
    let receivers: Vec<Receiver> = (0..64)
        .map(|i| Receiver {
            position: [(i % 16) as f32 * 0.4 - 3.0, (i / 16) as f32 * 0.5, 0.0],
            normal: [0.0, 0.0, 1.0],
            object: 0,
        })
        .collect();
    let depths: Vec<f32> = (0..=DEPTH_INTERVALS).map(|k| -1.0 - 1.3 * k as f32 / DEPTH_INTERVALS as f32).collect();
    for order in [4, 8] {
        c.bench_function(&format!("caps400/walk per receiver/order{order}"), |b| {
            b.iter(|| {
                let mut total = 0.0f32;
                for r in &receivers {
                    let (p, n) = (r.position.map(f64::from), r.normal.map(f64::from));
                    let mut acc = [0.0f32; MAX_COEFFICIENTS];
                    let mut zonal = [0.0f32; 8];
                    tree.visit(p, n, 0, |s, share| {
                        let centre = s.center.map(|c| c as f32);
                        if let BlockerView::Cap { direction, alpha, weight } =
                            view_blocker(r.position, r.normal, centre, s.radius as f32, false)
                        {
                            let depth =
                                overlapped_depth(depth_at(&depths, alpha), share as f32, LOG_EPSILON, depths[0]);
                            cap_log_zh(order, depth, alpha, &mut zonal[..order]);
                            add_rotated_zonal(order, &zonal[..order], weight, direction, &mut acc[..order * order]);
                        }
                    });
                    total += acc[0];
                }
                black_box(total)
            })
        });
        let packet = CapPacket::new(&tree, order, &depths, LOG_EPSILON, false);
        c.bench_function(&format!("caps400/packets of 8/order{order}"), |b| {
            b.iter(|| {
                let mut total = 0.0f32;
                let mut out = [[0.0f32; MAX_COEFFICIENTS]; LANES];
                for chunk in receivers.chunks(LANES) {
                    packet.sum(black_box(chunk), &mut out);
                    total += out.iter().map(|o| o[0]).sum::<f32>();
                }
                black_box(total)
            })
        });
    }
}

/// One receiver's horizons at the default settings (16 azimuths, bicubic levels, maximum
/// over steps) on a rough 129 x 129 field, for 16 points on it.
fn horizons(c: &mut Criterion) {
    use logsh::heightfield::{HeightField, HorizonPyramid, HorizonSettings};
    let n = 129;
    let heights: Vec<f32> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f32 * 0.1, (i / n) as f32 * 0.1);
            (1.3 * x).sin() * (0.7 * y).cos() + 0.3 * (3.1 * x + 2.3 * y).sin()
        })
        .collect();
    let field = HeightField::new(heights, n, n, [0.0, 0.0], [12.8, 12.8]).expect("a valid field");
    let pyramid = HorizonPyramid::new(&field, HorizonSettings::default()).expect("default settings");
    let points: Vec<[f64; 3]> = (0..16)
        .map(|i| {
            let (x, y) = (0.7 + 0.77 * i as f64, 6.4 + 3.0 * (i as f64).sin());
            [x, y, field.height_at(x, y)]
        })
        .collect();
    c.bench_function("horizons16/129x129", |b| {
        b.iter(|| {
            let mut out = [0.0f64; 16];
            let mut sum = 0.0;
            for p in &points {
                pyramid.horizon_elevations(black_box(*p), &mut out);
                sum += out.iter().sum::<f64>();
            }
            black_box(sum)
        })
    });
}

/// A glossy lobe's prefiltered map from nothing, as a relight's or a shade's first frame
/// computes it: every texel of a 256 x 128 sky's map for the lobes of the sample scenes
/// (`cones`: Phong 61, read through GGX; a lacquer, GGX of Phong 300).
fn prefiltered_maps(c: &mut Criterion) {
    use logsh::scene::EnvironmentMap;
    use logsh::shade::glossy::{ggx_alpha, MapLevels, SharpLobe};
    let (width, height) = (256, 128);
    let texels = (0..width * height)
        .map(|i| {
            let (u, v) = ((i % width) as f32 / width as f32, 1.0 - (i / width) as f32 / height as f32);
            let window = if (0.5..0.55).contains(&u) && (0.6..0.75).contains(&v) { 20.0 } else { 0.0 };
            [0.3 + 0.4 * v + window, 0.4 + 0.3 * v + window, 0.6 + 0.3 * v + window]
        })
        .collect();
    let map = EnvironmentMap { file: "sky".into(), width, height, texels };
    let levels = MapLevels::new(&map, 1.0, true);
    for (name, exponent) in [("phong61", 61.0), ("phong300", 300.0)] {
        let lobe = SharpLobe::Ggx { alpha: ggx_alpha(exponent) };
        c.bench_function(&format!("prefiltered map/{name}/256x128 sky"), |b| {
            b.iter(|| {
                let prefiltered = levels.prefilter(black_box(lobe));
                let mut sum = 0.0f32;
                for row in 0..prefiltered.height {
                    for column in 0..prefiltered.width {
                        sum += prefiltered.texel(column, row)[1];
                    }
                }
                black_box(sum)
            })
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(1)).warm_up_time(std::time::Duration::from_millis(300));
    targets = exponentiation, lighting, blockers, blocker_packets, horizons, prefiltered_maps
}
criterion_main!(benches);
