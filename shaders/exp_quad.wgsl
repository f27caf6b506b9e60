// exp*(f) . L by Gauss quadrature on the sphere (src/sh/exp.rs, ExactExp::exp_below):
// the sum over the grid's nodes of w exp(min(f(node), ceiling)) L(node), with w L(node)
// tabulated by the host (the light folded in, src/sh/folded.rs); the caller clamps at 0.
// Nodes are clamped at the log of the lobe's peak (the true function never exceeds it):
// this only removes ringing.
//
// The sum runs in separable form (src/sh/separable.rs): per Gauss row, C_m and S_m of f
// from the row's factors R_lm (ORDER^2 multiply-adds), then per azimuth
// f = sum_m C_m cos(m phi) + S_m sin(m phi) by Clenshaw's recurrence, which reads no
// table; the node-major basis table it replaces cost ORDER^2 reads and multiply-adds per
// node.
//
// With OVERLAP_FLOOR, the log visibility v (a part of f) is floored at log(eps) at every
// node, `f - v + max(v, log eps)` (exp.rs, ExactExp::exp_floored): a direction behind
// several clamped terms is clamped once.
fn quad_exp_dot_light(f: ptr<function, array<f32, COUNT_CAP>>, v: ptr<function, array<f32, COUNT_CAP>>, ceiling: f32) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    var factor = T_QUAD_ROWS;
    for (var row = 0u; row < QUAD_ROWS; row++) {
        var fc: array<f32, ORDER_CAP>;
        var fs: array<f32, ORDER_CAP>;
        var vc: array<f32, ORDER_CAP>;
        var vs: array<f32, ORDER_CAP>;
        for (var m = 0u; m < ORDER; m++) {
            for (var l = m; l < ORDER; l++) {
                let r = tables[factor];
                factor++;
                let centre = l * (l + 1u);
                fc[m] += r * (*f)[centre + m];
                if OVERLAP_FLOOR {
                    vc[m] += r * (*v)[centre + m];
                }
                if m > 0u {
                    fs[m] += r * (*f)[centre - m];
                    if OVERLAP_FLOOR {
                        vs[m] += r * (*v)[centre - m];
                    }
                }
            }
        }
        for (var j = 0u; j < QUAD_AZIMUTHS; j++) {
            let cos_phi = tables[T_QUAD_AZIMUTHS + 2u * j];
            let sin_phi = tables[T_QUAD_AZIMUTHS + 2u * j + 1u];
            let two_cos = 2.0 * cos_phi;
            // Clenshaw from m = ORDER - 1 down to 1, f and v side by side (x: cosine
            // series, y: sine series).
            var f1 = vec2<f32>(0.0);
            var f2 = vec2<f32>(0.0);
            var v1 = vec2<f32>(0.0);
            var v2 = vec2<f32>(0.0);
            for (var k = 1u; k < ORDER; k++) {
                let m = ORDER - k;
                let fb = vec2<f32>(fc[m], fs[m]) + two_cos * f1 - f2;
                f2 = f1;
                f1 = fb;
                if OVERLAP_FLOOR {
                    let vb = vec2<f32>(vc[m], vs[m]) + two_cos * v1 - v2;
                    v2 = v1;
                    v1 = vb;
                }
            }
            var value = fc[0] + f1.x * cos_phi - f2.x + f1.y * sin_phi;
            if OVERLAP_FLOOR {
                let visibility = vc[0] + v1.x * cos_phi - v2.x + v1.y * sin_phi;
                value += max(params.log_epsilon - visibility, 0.0);
            }
            let light = T_NODE_LIGHT + 3u * (row * QUAD_AZIMUTHS + j);
            sum += exp(min(value, ceiling)) * vec3<f32>(tables[light], tables[light + 1u], tables[light + 2u]);
        }
    }
    return sum;
}

// An SH vector dotted with the light per colour channel (kernel.rs, lit; the caller
// clamps at 0).
fn dot_light(e: ptr<function, array<f32, COUNT_CAP>>) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    for (var i = 0u; i < COUNT; i++) {
        sum += (*e)[i] * vec3<f32>(tables[T_LIGHT + i], tables[T_LIGHT + COUNT + i], tables[T_LIGHT + 2u * COUNT + i]);
    }
    return sum;
}

// |f^|: the norm of the non-DC coefficients.
fn non_dc_magnitude(f: ptr<function, array<f32, COUNT_CAP>>) -> f32 {
    var sum = 0.0;
    for (var i = 1u; i < COUNT; i++) {
        sum += (*f)[i] * (*f)[i];
    }
    return sqrt(sum);
}
