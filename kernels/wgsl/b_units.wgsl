// The CPU GEMM's B as a storage buffer of units (`Unit`, `unit_f32` from the prelude).
@group(0) @binding(1) var<storage, read> b: array<Unit>;

// Four values of B from unit `i`, as f32.
fn b_at(i: u32) -> vec4<f32> {
    return unit_f32(b[i]);
}
