// Channel concatenation of NHWC tensors: out[pix] = [a[pix] (C1 channels), b[pix] (C2 channels)];
// n, c1 and c2 count units (unit_1.wgsl / unit_4.wgsl).
@group(0) @binding(0) var<storage, read> a: array<U>;
@group(0) @binding(1) var<storage, read> b: array<U>;
@group(0) @binding(2) var<storage, read_write> out: array<U>;

struct Params {
    n: u32,
    c1: u32,
    c2: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let c = p.c1 + p.c2;
    let pix = i / c;
    let ch = i % c;
    if ch < p.c1 {
        out[i] = a[pix * p.c1 + ch];
    } else {
        out[i] = b[pix * p.c2 + ch - p.c1];
    }
}
