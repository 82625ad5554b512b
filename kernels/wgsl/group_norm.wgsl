// GroupNorm over NHWC: one workgroup per (group, batch); mean and variance in two passes (f32),
// then the affine map, optionally followed by SiLU (the ResNet block's norm + activation).
// Channels count units (unit_1/2/4.wgsl), hw pixels.
@group(0) @binding(0) var<storage, read> x: array<U>;
@group(0) @binding(1) var<storage, read> gamma: array<U>;
@group(0) @binding(2) var<storage, read> beta: array<U>;
@group(0) @binding(3) var<storage, read_write> y: array<U>;

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
    let m = group_moments(base, count, cg, p.c, lid);
    group_apply(base, count, cg, p.c, c0, m.x, inverseSqrt(m.y / f32(count * UNIT) + p.eps), p.silu != 0u, lid);
}
