// Element-wise and GroupNorm kernels move one value per invocation step (unit_2.wgsl: two,
// unit_4.wgsl: four). They compute in vec4<f32> either way; here the unused components fold away.
alias U = S;
const UNIT: u32 = 1u;

fn widen(u: U) -> vec4<f32> {
    return vec4<f32>(f32(u));
}

fn narrow(v: vec4<f32>) -> U {
    return U(v.x);
}

// The sum of a widened unit's values.
fn total(v: vec4<f32>) -> f32 {
    return v.x;
}
