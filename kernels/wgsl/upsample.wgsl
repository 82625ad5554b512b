// Nearest-neighbour 2× upsampling of NHWC: out[b, y, x, c] = in[b, y/2, x/2, c].
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> out: array<S>;

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
    let ch = i % p.c;
    let pix = i / p.c;
    let ox = pix % (2u * p.w);
    let rest = pix / (2u * p.w);
    let oy = rest % (2u * p.h);
    let batch = rest / (2u * p.h);
    out[i] = x[((batch * p.h + oy / 2u) * p.w + ox / 2u) * p.c + ch];
}
