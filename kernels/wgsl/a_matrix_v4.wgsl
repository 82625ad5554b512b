// A operand read as vec4 along K (K, lda and a_batch multiples of 4; the runtime picks another
// variant otherwise).
@group(0) @binding(0) var<storage, read> a: array<U4>;

const A_VEC: u32 = 4u;

// The unit at row context r and column k, as stored (the matrix-unit kernels stage it so, with
// no round trip through f32, which not every compiler folds: NVK's did not). row_ctx and k_ctx
// clamp into A, so the read is always in bounds; a matrix has no padding, so every unit is inside
// (the callers mask the columns past K).
fn a_unit(r: RowCtx, k: KCtx) -> U4 {
    return a[(r + k) / 4u];
}

fn a_unit_inside(r: RowCtx, k: KCtx) -> bool {
    return true;
}
