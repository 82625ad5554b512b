// The output side of the vec4 GEMM kernels (N, ldc and c_batch multiples of 4): C = alpha·sum
// (+ bias) (+ C), then ReLU when asked, for four consecutive columns from `col` (a multiple of
// 4), skipped past the edges of C.
@group(0) @binding(2) var<storage, read> bias: array<vec4<S>>;
@group(0) @binding(3) var<storage, read_write> c: array<vec4<S>>;

fn store4(batch: u32, row: u32, col: u32, sum: vec4<f32>) {
    if row >= p.g.m || col >= p.g.n {
        return;
    }
    let at = (batch * p.g.c_batch + row * p.g.ldc + col) / 4u;
    var v = p.g.alpha * sum;
    if (p.g.flags & FLAG_BIAS) != 0u {
        v += vec4<f32>(bias[col / 4u]);
    }
    if (p.g.flags & FLAG_ACCUMULATE) != 0u {
        v += vec4<f32>(c[at]);
    }
    if (p.g.flags & FLAG_RELU) != 0u {
        v = max(v, vec4<f32>(0.0));
    }
    c[at] = vec4<S>(v);
}
