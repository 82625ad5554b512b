// GEGLU four values per invocation (F % 4 = 0).
@group(0) @binding(0) var<storage, read> x: array<vec4<S>>;
@group(0) @binding(1) var<storage, read_write> out: array<vec4<S>>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i < p.n {
        let at = value_at(i);
        let g = vec4<f32>(x[at + p.f]);
        let gelu = vec4<f32>(gelu_erf(g.x), gelu_erf(g.y), gelu_erf(g.z), gelu_erf(g.w));
        out[i] = vec4<S>(vec4<f32>(x[at]) * gelu);
    }
}
