// A operand of an implicit-GEMM convolution (taps in conv_taps.wgsl), read one element at a
// time so any channel count works (the VAE's RGB input has Cin = 3).
@group(0) @binding(0) var<storage, read> a: array<S>;

const A_VEC: u32 = 1u;

fn load_a1(r: RowCtx, k: KCtx) -> f32 {
    let t = tap(r, k);
    return select(0.0, f32(a[t.at]), t.inside);
}
