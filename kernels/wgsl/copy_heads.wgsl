// Multi-head tensors between layouts, any strides: for every (batch, token, head, d < dst_d),
// dst[dst_off + batch·dst_batch + token·dst_ld + head·dst_d + d] =
//     src[src_off + batch·src_batch + token·src_ld + head·src_d + d] where d < src_d, else 0.
// Attention pads head sizes that are not a multiple of 4 into its vec4 layout with this, and
// takes the padding off again; convolutions pad channels the same way. SRC and DST are the
// storage types (heads_as_stored.wgsl, or heads_to_f32.wgsl / heads_from_f32.wgsl, which widen
// f16 heads for f32 arithmetic and narrow the results back).
@group(0) @binding(0) var<storage, read> src: array<SRC>;
@group(0) @binding(1) var<storage, read_write> dst: array<DST>;

struct Params {
    n: u32,
    tokens: u32,
    heads: u32,
    src_d: u32,
    dst_d: u32,
    src_ld: u32,
    dst_ld: u32,
    src_batch: u32,
    dst_batch: u32,
    src_off: u32,
    dst_off: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let d = i % p.dst_d;
    let row = i / p.dst_d;
    let head = row % p.heads;
    let token = (row / p.heads) % p.tokens;
    let batch = row / (p.heads * p.tokens);
    let at = p.dst_off + batch * p.dst_batch + token * p.dst_ld + head * p.dst_d + d;
    if d < p.src_d {
        dst[at] = DST(src[p.src_off + batch * p.src_batch + token * p.src_ld + head * p.src_d + d]);
    } else {
        dst[at] = DST(0.0);
    }
}
