// A operand: a row-major matrix (row stride lda, batch stride a_batch), read as vec4 along K.
// Needs K, lda and a_batch to be multiples of 4; the runtime picks another variant otherwise.
@group(0) @binding(0) var<storage, read> a: array<vec4<S>>;

struct AParams {
    lda: u32,
    a_batch: u32,
}

alias RowCtx = u32;
alias KCtx = u32;

fn row_ctx(batch: u32, row: u32) -> RowCtx {
    // Rows past M are clamped, not masked: their results are never stored.
    return batch * p.a.a_batch + min(row, p.g.m - 1u) * p.a.lda;
}

fn k_ctx(k: u32) -> KCtx {
    return min(k, p.g.k - 4u);
}

fn load_a(r: RowCtx, k: KCtx) -> vec4<f32> {
    return vec4<f32>(a[(r + k) / 4u]);
}
