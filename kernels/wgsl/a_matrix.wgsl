// A operand read one element at a time (any shape).
@group(0) @binding(0) var<storage, read> a: array<S>;

const A_VEC: u32 = 1u;

fn load_a1(r: RowCtx, k: KCtx) -> f32 {
    return f32(a[r + k]);
}
