// LayerNorm over the last dimension: one workgroup per row, two-pass mean/variance in f32.
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read> gamma: array<S>;
@group(0) @binding(2) var<storage, read> beta: array<S>;
@group(0) @binding(3) var<storage, read_write> y: array<S>;

struct Params {
    c: u32,
    eps: f32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let base = (wg.y * p.groups_x + wg.x) * p.c;
    var s = 0.0;
    for (var i = lid; i < p.c; i += WG) {
        s += f32(x[base + i]);
    }
    let mean = workgroup_sum(s, lid) / f32(p.c);
    var q = 0.0;
    for (var i = lid; i < p.c; i += WG) {
        let d = f32(x[base + i]) - mean;
        q += d * d;
    }
    let rstd = inverseSqrt(workgroup_sum(q, lid) / f32(p.c) + p.eps);
    for (var i = lid; i < p.c; i += WG) {
        y[base + i] = S((f32(x[base + i]) - mean) * rstd * f32(gamma[i]) + f32(beta[i]));
    }
}
