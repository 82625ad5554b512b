// y = f(x) element-wise; OP: 0 scale (alpha·x), 1 SiLU, 2 GELU (erf), 3 GELU (tanh), 4 quick-GELU.
// x and y may be the same buffer.
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> y: array<S>;

struct Params {
    n: u32,
    alpha: f32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let v = f32(x[i]);
    var r: f32;
    switch OP {
        case 0u: { r = p.alpha * v; }
        case 1u: { r = silu(v); }
        case 2u: { r = gelu_erf(v); }
        case 3u: { r = gelu_tanh(v); }
        default: { r = quick_gelu(v); }
    }
    y[i] = S(r);
}
