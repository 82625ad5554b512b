// The CPU GEMM's A (a row-major matrix, a_matrix_rows.wgsl) as a uniform texel buffer of f32
// RGBA texels, bound where B is read from texels too (TA = 1 in f32; b_texels.wgsl says why).
@group(0) @binding(0) var a: texture_1d<f32>;

const A_VEC: u32 = 4u;

// Four values of A along K from row context r and column k.
fn load_a(r: RowCtx, k: KCtx) -> vec4<f32> {
    return textureLoad(a, i32((r + k) / 4u), 0);
}
