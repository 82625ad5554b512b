// Nearest-neighbour 2× upsampling of NHWC: out[b, y, x, c] = in[b, y/2, x/2, c]; n and c count
// units (unit_1.wgsl / unit_4.wgsl).
@group(0) @binding(0) var<storage, read> x: array<U>;
@group(0) @binding(1) var<storage, read_write> out: array<U>;

struct Params {
    n: u32,
    h: u32,
    w: u32,
    c: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let at = nhwc_position(i, 2u * p.h, 2u * p.w, p.c);
    out[i] = x[((at.x * p.h + at.y / 2u) * p.w + at.z / 2u) * p.c + at.w];
}
