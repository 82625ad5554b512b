// A operand of an implicit-GEMM convolution (taps in conv_taps.wgsl), read as vec4 along Cin
// (Cin % 4 = 0).
@group(0) @binding(0) var<storage, read> a: array<U4>;

const A_VEC: u32 = 4u;

// The unit a tap reads, as stored (see a_matrix_v4.wgsl): in bounds, whether or not the tap
// falls in the padding, which a_unit_inside says.
fn a_unit(r: RowCtx, k: KCtx) -> U4 {
    return a[tap(r, k).at / 4u];
}

fn a_unit_inside(r: RowCtx, k: KCtx) -> bool {
    return tap(r, k).inside;
}
