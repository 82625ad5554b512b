// A operand read as vec4 along K (K, lda and a_batch multiples of 4; the runtime picks another
// variant otherwise).
@group(0) @binding(0) var<storage, read> a: array<vec4<S>>;

const A_VEC: u32 = 4u;

fn load_a(r: RowCtx, k: KCtx) -> vec4<f32> {
    return vec4<f32>(a[(r + k) / 4u]);
}
