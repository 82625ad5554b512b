// A tensor copied into a channel slice of a wider NHWC tensor: out[pix, offset + ch] = x[pix, ch].
// Concatenating k branches is k of these, with no intermediate tensors.
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> out: array<S>;

struct Params {
    n: u32,
    c: u32,
    c_out: u32,
    offset: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    out[(i / p.c) * p.c_out + p.offset + i % p.c] = x[i];
}
