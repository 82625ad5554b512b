// GroupNorm over NHWC: one workgroup per (group, batch); mean and variance in two passes (f32),
// then the affine map, optionally followed by SiLU (the ResNet block's norm + activation).
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read> gamma: array<S>;
@group(0) @binding(2) var<storage, read> beta: array<S>;
@group(0) @binding(3) var<storage, read_write> y: array<S>;

struct Params {
    hw: u32,
    c: u32,
    groups: u32,
    eps: f32,
    silu: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let cg = p.c / p.groups;
    let count = p.hw * cg;
    let c0 = wg.x * cg;
    let base = wg.y * p.hw * p.c + c0;
    var s = 0.0;
    for (var e = lid; e < count; e += WG) {
        s += f32(x[base + (e / cg) * p.c + e % cg]);
    }
    let mean = workgroup_sum(s, lid) / f32(count);
    var q = 0.0;
    for (var e = lid; e < count; e += WG) {
        let d = f32(x[base + (e / cg) * p.c + e % cg]) - mean;
        q += d * d;
    }
    let rstd = inverseSqrt(workgroup_sum(q, lid) / f32(count) + p.eps);
    for (var e = lid; e < count; e += WG) {
        let at = base + (e / cg) * p.c + e % cg;
        let ch = c0 + e % cg;
        var v = (f32(x[at]) - mean) * rstd * f32(gamma[ch]) + f32(beta[ch]);
        if p.silu != 0u {
            v = v / (1.0 + exp(-v));
        }
        y[at] = S(v);
    }
}
