// A operand: a row-major matrix (row stride lda, batch stride a_batch), read one element at a time.
@group(0) @binding(0) var<storage, read> a: array<S>;

struct AParams {
    lda: u32,
    a_batch: u32,
}

alias RowCtx = u32;
alias KCtx = u32;

fn row_ctx(batch: u32, row: u32) -> RowCtx {
    return batch * p.a.a_batch + min(row, p.g.m - 1u) * p.a.lda;
}

fn k_ctx(k: u32) -> KCtx {
    return k;
}

fn load_a1(r: RowCtx, k: KCtx) -> f32 {
    return f32(a[r + min(k, p.g.k - 1u)]);
}
