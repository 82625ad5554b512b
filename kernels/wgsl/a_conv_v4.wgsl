// A operand of an implicit-GEMM convolution (taps in conv_taps.wgsl), read in units of UW values
// along Cin (Cin % UW = 0).
@group(0) @binding(0) var<storage, read> a: array<Unit>;

// The unit a tap reads, as stored (see a_matrix_v4.wgsl): in bounds, whether or not the tap
// falls in the padding, which a_unit_inside says.
fn a_unit(r: RowCtx, k: KCtx) -> Unit {
    return a[tap(r, k).at / UW];
}

fn a_unit_inside(r: RowCtx, k: KCtx) -> bool {
    return tap(r, k).inside;
}
