// The SH triple product with the host's sparse tripling tensor (src/sh/product.rs):
// out_i = sum over (j <= k) of gamma_ijk (f_j g_k + f_k g_j), halved on the diagonal.
fn sh_product(f: ptr<function, array<f32, COUNT_CAP>>, g: ptr<function, array<f32, COUNT_CAP>>, out: ptr<function, array<f32, COUNT_CAP>>) {
    for (var i = 0u; i < COUNT; i++) {
        let begin = table_u32(T_TENSOR_ROWS + i);
        let end = table_u32(T_TENSOR_ROWS + i + 1u);
        var sum = 0.0;
        for (var e = begin; e < end; e++) {
            let pair = table_u32(T_TENSOR_ENTRIES + 2u * e);
            let j = pair & 0xffffu;
            let k = pair >> 16u;
            let gamma = tables[T_TENSOR_ENTRIES + 2u * e + 1u];
            if j == k {
                sum += gamma * (*f)[j] * (*g)[k];
            } else {
                sum += gamma * ((*f)[j] * (*g)[k] + (*f)[k] * (*g)[j]);
            }
        }
        (*out)[i] = sum;
    }
}
