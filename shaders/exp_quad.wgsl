// exp*(f) . L by Gauss quadrature on the sphere (src/sh/exp.rs, ExactExp::exp_below):
// the sum over the NODES nodes of w exp(min(f(node), ceiling)) L(node). The CPU path
// projects exp(f) onto the basis and then dots with L; folding L into the node table
// (L(node) = sum_i L_i y_i(node), host-generated) is the same sum in another order, at
// half the cost; the caller clamps at 0. Nodes are clamped at the log of the lobe's peak (the true function never
// exceeds it): this only removes ringing.
//
// With OVERLAP_FLOOR, the log visibility v (a part of f) is floored at log(eps) at every
// node, `f - v + max(v, log eps)` (exp.rs, ExactExp::exp_floored): a direction behind
// several clamped terms is clamped once.
fn quad_exp_dot_light(f: ptr<function, array<f32, COUNT_CAP>>, v: ptr<function, array<f32, COUNT_CAP>>, ceiling: f32) -> vec3<f32> {
    // Rows of the basis table are padded with zeros to a multiple of 4 (as is f), so the
    // node value is a sum of vec4 dot products.
    let quads = (COUNT + 3u) / 4u;
    var sum = vec3<f32>(0.0);
    for (var node = 0u; node < NODES; node++) {
        let basis = T_QUAD_BASIS + node * 4u * quads;
        var value = 0.0;
        for (var j = 0u; j < quads; j++) {
            let b = basis + 4u * j;
            let y = vec4<f32>(tables[b], tables[b + 1u], tables[b + 2u], tables[b + 3u]);
            value += dot(y, vec4<f32>((*f)[4u * j], (*f)[4u * j + 1u], (*f)[4u * j + 2u], (*f)[4u * j + 3u]));
        }
        if OVERLAP_FLOOR {
            var visibility = 0.0;
            for (var j = 0u; j < quads; j++) {
                let b = basis + 4u * j;
                let y = vec4<f32>(tables[b], tables[b + 1u], tables[b + 2u], tables[b + 3u]);
                visibility += dot(y, vec4<f32>((*v)[4u * j], (*v)[4u * j + 1u], (*v)[4u * j + 2u], (*v)[4u * j + 3u]));
            }
            value += max(params.log_epsilon - visibility, 0.0);
        }
        let e = tables[T_QUAD_WEIGHTS + node] * exp(min(value, ceiling));
        let light = T_NODE_LIGHT + 3u * node;
        sum += e * vec3<f32>(tables[light], tables[light + 1u], tables[light + 2u]);
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
