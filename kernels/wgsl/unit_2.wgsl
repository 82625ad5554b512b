// Two consecutive values per step as one vec2 (GroupNorm where a group's channels are even,
// as SDXL's 10 of 320 are); see unit_1.wgsl.
alias U = vec2<S>;
const UNIT: u32 = 2u;

fn widen(u: U) -> vec4<f32> {
    let v = vec2<f32>(u);
    return vec4<f32>(v, v);
}

fn narrow(v: vec4<f32>) -> U {
    return U(v.xy);
}

fn total(v: vec4<f32>) -> f32 {
    return v.x + v.y;
}
