// GEGLU: x is [rows, 2F]; out[r, f] = x[r, f] · GELU_erf(x[r, F + f]) (diffusers: value first,
// gate second).
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> out: array<S>;

struct Params {
    n: u32,
    f: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let at = (i / p.f) * 2u * p.f + i % p.f;
    out[i] = S(f32(x[at]) * gelu_erf(f32(x[at + p.f])));
}
