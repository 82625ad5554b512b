// Softmax over the last dimension of scale·x: one workgroup per row, max-subtracted, f32.
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> y: array<S>;

struct Params {
    c: u32,
    scale: f32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let base = (wg.y * p.groups_x + wg.x) * p.c;
    var m = -3.0e38;
    for (var i = lid; i < p.c; i += WG) {
        m = max(m, p.scale * f32(x[base + i]));
    }
    m = workgroup_max(m, lid);
    var s = 0.0;
    for (var i = lid; i < p.c; i += WG) {
        s += exp(p.scale * f32(x[base + i]) - m);
    }
    let inv = 1.0 / workgroup_sum(s, lid);
    for (var i = lid; i < p.c; i += WG) {
        y[base + i] = S(exp(p.scale * f32(x[base + i]) - m) * inv);
    }
}
