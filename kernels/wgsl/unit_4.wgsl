// Four consecutive values per step as one vec4 (the runtime takes this variant where every count
// the kernel indexes by is a multiple of 4, and passes the counts in units of four); see
// unit_1.wgsl.
alias U = vec4<S>;
const UNIT: u32 = 4u;

fn widen(u: U) -> vec4<f32> {
    return vec4<f32>(u);
}

fn narrow(v: vec4<f32>) -> U {
    return U(v);
}

fn total(v: vec4<f32>) -> f32 {
    return v.x + v.y + v.z + v.w;
}
