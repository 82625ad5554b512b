// A operand read as vec4 along K (K, lda and a_batch multiples of 4; the runtime picks another
// variant otherwise).
@group(0) @binding(0) var<storage, read> a: array<vec4<S>>;

const A_VEC: u32 = 4u;

// As stored: the matrix-unit kernels stage it so, with no round trip through f32 (which not
// every compiler folds: NVK's did not).
fn load_a_stored(r: RowCtx, k: KCtx) -> vec4<S> {
    return a[(r + k) / 4u];
}

fn load_a(r: RowCtx, k: KCtx) -> vec4<f32> {
    return vec4<f32>(load_a_stored(r, k));
}
