// GEGLU one value per invocation (any F).
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> out: array<S>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i < p.n {
        let at = value_at(i);
        out[i] = S(f32(x[at]) * gelu_erf(f32(x[at + p.f])));
    }
}
