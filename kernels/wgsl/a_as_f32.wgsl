// The A unit widened to f32 and zero in a convolution's padding, for the kernels that multiply
// in f32.
fn load_a(r: RowCtx, k: KCtx) -> vec4<f32> {
    return select(vec4<f32>(0.0), unit_f32(a_unit(r, k)), a_unit_inside(r, k));
}
