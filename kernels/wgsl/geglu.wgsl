// GEGLU: x is [rows, 2F], out[r, f] = x[r, f] · GELU_erf(x[r, F + f]) (diffusers: value first,
// gate second); n and f count units (unit_1.wgsl / unit_4.wgsl: F % 4 = 0 takes vec4s).
@group(0) @binding(0) var<storage, read> x: array<U>;
@group(0) @binding(1) var<storage, read_write> out: array<U>;

struct Params {
    n: u32,
    f: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i < p.n {
        let at = (i / p.f) * 2u * p.f + i % p.f;
        let g = widen(x[at + p.f]);
        out[i] = narrow(widen(x[at]) * vec4<f32>(gelu_erf(g.x), gelu_erf(g.y), gelu_erf(g.z), gelu_erf(g.w)));
    }
}
