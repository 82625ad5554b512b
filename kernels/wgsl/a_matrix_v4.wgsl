// A operand read in units of UW values along K (K, lda and a_batch multiples of UW; the runtime
// picks another variant otherwise).
@group(0) @binding(0) var<storage, read> a: array<Unit>;

const A_VEC: u32 = UW;

// The unit at row context r and column k, as stored (the matrix-unit kernels stage it so, with
// no round trip through f32, which not every compiler folds: NVK's did not). row_ctx and k_ctx
// clamp into A, so the read is always in bounds; a matrix has no padding, so every unit is inside
// (the callers mask the columns past K).
fn a_unit(r: RowCtx, k: KCtx) -> Unit {
    return a[(r + k) / UW];
}

fn a_unit_inside(r: RowCtx, k: KCtx) -> bool {
    return true;
}
