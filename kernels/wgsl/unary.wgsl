// y = f(x) element-wise; OP: 0 scale (alpha·x), 1 SiLU, 2 GELU (erf), 3 GELU (tanh), 4 quick-GELU.
// x and y may be the same buffer. n counts units (unit_1.wgsl / unit_4.wgsl).
@group(0) @binding(0) var<storage, read> x: array<U>;
@group(0) @binding(1) var<storage, read_write> y: array<U>;

struct Params {
    n: u32,
    alpha: f32,
    groups_x: u32,
}

var<immediate> p: Params;

fn op(v: f32) -> f32 {
    switch OP {
        case 0u: { return p.alpha * v; }
        case 1u: { return silu(v); }
        case 2u: { return gelu_erf(v); }
        case 3u: { return gelu_tanh(v); }
        default: { return quick_gelu(v); }
    }
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let v = widen(x[i]);
    y[i] = narrow(vec4<f32>(op(v.x), op(v.y), op(v.z), op(v.w)));
}
