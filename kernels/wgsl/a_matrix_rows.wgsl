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

// Walking K a step at a time (gemm_coop.wgsl): the column itself, clamped where it is read.
alias KWalk = u32;
alias KStep = u32;

fn k_walk(k: u32) -> KWalk {
    return k;
}

fn k_step(s: u32) -> KStep {
    return s;
}

fn k_next(k: KWalk, s: KStep) -> KWalk {
    return k + s;
}

fn k_at(k: KWalk) -> KCtx {
    return k_ctx(k);
}
