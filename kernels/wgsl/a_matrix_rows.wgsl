// Shared by the matrix A loaders: a row-major matrix with row stride lda and batch stride
// a_batch. The loader file defines A_VEC (elements per load).
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
    return min(k, p.g.k - A_VEC);
}
