// Element-wise kernels move one value per invocation (unit_4.wgsl: four). They compute in
// vec4<f32> either way; here the three unused components fold away.
alias U = S;

fn widen(u: U) -> vec4<f32> {
    return vec4<f32>(f32(u));
}

fn narrow(v: vec4<f32>) -> U {
    return U(v.x);
}
