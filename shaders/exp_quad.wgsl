// exp*(f) . L by Gauss quadrature on the sphere (src/sh/exp.rs, ExactExp::exp_below):
// the sum over the NODES nodes of w exp(min(f(node), ceiling)) L(node). The CPU path
// projects exp(f) onto the basis and then dots with L; folding L into the node table
// (L(node) = sum_i L_i y_i(node), host-generated) is the same sum in another order, at
// half the cost. Nodes are clamped at the log of the lobe's peak (the true function never
// exceeds it): this only removes ringing.
fn quad_exp_dot_light(f: ptr<function, array<f32, COUNT>>, ceiling: f32) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    for (var node = 0u; node < NODES; node++) {
        let basis = T_QUAD_BASIS + node * COUNT;
        var value = 0.0;
        for (var i = 0u; i < COUNT; i++) {
            value += tables[basis + i] * (*f)[i];
        }
        let e = tables[T_QUAD_WEIGHTS + node] * exp(min(value, ceiling));
        let light = T_NODE_LIGHT + 3u * node;
        sum += e * vec3<f32>(tables[light], tables[light + 1u], tables[light + 2u]);
    }
    return max(sum, vec3<f32>(0.0));
}

// An SH vector dotted with the light per colour channel, clamped at 0 (kernel.rs, lit).
fn dot_light(e: ptr<function, array<f32, COUNT>>) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    for (var i = 0u; i < COUNT; i++) {
        sum += (*e)[i] * vec3<f32>(tables[T_LIGHT + i], tables[T_LIGHT + COUNT + i], tables[T_LIGHT + 2u * COUNT + i]);
    }
    return max(sum, vec3<f32>(0.0));
}

// |f^|: the norm of the non-DC coefficients.
fn non_dc_magnitude(f: ptr<function, array<f32, COUNT>>) -> f32 {
    var sum = 0.0;
    for (var i = 1u; i < COUNT; i++) {
        sum += (*f)[i] * (*f)[i];
    }
    return sqrt(sum);
}
