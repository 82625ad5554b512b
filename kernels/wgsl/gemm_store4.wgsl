// The output side of the vec4 GEMM kernels (N, ldc and c_batch multiples of 4): C = alpha·sum
// (+ bias) (+ C), then ReLU when asked, for four consecutive columns from `col` (a multiple of
// 4), skipped past the edges of C.
@group(0) @binding(2) var<storage, read> bias: array<vec4<S>>;
@group(0) @binding(3) var<storage, read_write> c: array<vec4<S>>;

fn store4(batch: u32, row: u32, col: u32, sum: vec4<f32>) {
    if (row >= p.g.m) | (col >= p.g.n) {
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

// GE = 1: four values of C from the sums of value columns col..col+3 and of their gates.
fn store_geglu4(batch: u32, row: u32, col: u32, value: vec4<f32>, gate: vec4<f32>) {
    if (row >= p.g.m) | (col >= p.g.n) {
        return;
    }
    var v = p.g.alpha * value;
    var g = p.g.alpha * gate;
    if (p.g.flags & FLAG_BIAS) != 0u {
        v += vec4<f32>(bias[b_row(col) / 4u]);
        g += vec4<f32>(bias[b_row(col + GB) / 4u]);
    }
    let at = (batch * p.g.c_batch + row * p.g.ldc + out_col(col)) / 4u;
    c[at] = vec4<S>(v * vec4<f32>(gelu_erf(g.x), gelu_erf(g.y), gelu_erf(g.z), gelu_erf(g.w)));
}
