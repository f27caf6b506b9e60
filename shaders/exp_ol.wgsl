// Optimal linear exponentiation (paper 000, Eq. 12; src/sh/exp.rs, OlTable):
// exp*(f) = exp(f_0 y_0) (a(|f^|) ONE_DC e_0 + b(|f^|) f^), with a and b fitted by the
// host and read by linear interpolation on its magnitude grid (fine below 1, then steps
// of OL_COARSE_STEP).
fn ol_coefficients(magnitude: f32) -> vec2<f32> {
    var x = 0.0;
    if magnitude <= 1.0 {
        x = max(magnitude, 0.0) * f32(OL_FINE_NODES);
    } else {
        x = f32(OL_FINE_NODES) + (magnitude - 1.0) / OL_COARSE_STEP;
    }
    let i = min(u32(floor(x)), OL_NODES - 2u);
    let t = min(x - f32(i), 1.0);
    let a = tables[T_OL_A + i] + t * (tables[T_OL_A + i + 1u] - tables[T_OL_A + i]);
    let b = tables[T_OL_B + i] + t * (tables[T_OL_B + i + 1u] - tables[T_OL_B + i]);
    return vec2<f32>(a, b);
}

// out = OL's exp of the non-DC part `hat` (out[0] from a, the rest b * hat).
fn ol_exp_non_dc(hat: ptr<function, array<f32, COUNT_CAP>>, magnitude: f32, out: ptr<function, array<f32, COUNT_CAP>>) {
    let ab = ol_coefficients(magnitude);
    for (var i = 1u; i < COUNT; i++) {
        (*out)[i] = ab.y * (*hat)[i];
    }
    (*out)[0] = ab.x * ONE_DC;
}
