// A operand of an implicit-GEMM convolution (taps in conv_taps.wgsl), read as vec4 along Cin
// (Cin % 4 = 0).
@group(0) @binding(0) var<storage, read> a: array<vec4<S>>;

const A_VEC: u32 = 4u;

// As stored (see a_matrix_v4.wgsl).
fn load_a_stored(r: RowCtx, k: KCtx) -> vec4<S> {
    let t = tap(r, k);
    return select(vec4<S>(), a[t.at / 4u], t.inside);
}

fn load_a(r: RowCtx, k: KCtx) -> vec4<f32> {
    return vec4<f32>(load_a_stored(r, k));
}
