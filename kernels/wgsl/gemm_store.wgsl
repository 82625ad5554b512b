// The output side of the workgroup GEMM kernels: C = alpha·sum (+ bias) (+ C), then ReLU when
// asked, for one element, skipped past the edges of C.
@group(0) @binding(2) var<storage, read> bias: array<S>;
@group(0) @binding(3) var<storage, read_write> c: array<S>;

fn store(batch: u32, row: u32, col: u32, sum: f32) {
    if (row >= p.g.m) | (col >= p.g.n) {
        return;
    }
    let at = batch * p.g.c_batch + row * p.g.ldc + col;
    var v = p.g.alpha * sum;
    if (p.g.flags & FLAG_BIAS) != 0u {
        v += f32(bias[col]);
    }
    if (p.g.flags & FLAG_ACCUMULATE) != 0u {
        v += f32(c[at]);
    }
    if (p.g.flags & FLAG_RELU) != 0u {
        v = max(v, 0.0);
    }
    c[at] = S(v);
}

// GE = 1: one value of C from the sums of value column `col` and of its gate.
fn store_geglu(batch: u32, row: u32, col: u32, value: f32, gate: f32) {
    if (row >= p.g.m) | (col >= p.g.n) {
        return;
    }
    var v = p.g.alpha * value;
    var g = p.g.alpha * gate;
    if (p.g.flags & FLAG_BIAS) != 0u {
        v += f32(bias[b_row(col)]);
        g += f32(bias[b_row(col + GB)]);
    }
    c[batch * p.g.c_batch + row * p.g.ldc + out_col(col)] = S(v * gelu_erf(g));
}
