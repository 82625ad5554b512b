// GroupNorm statistics of one band of pixels of one image (a tensor too large for one binding is
// normalised band by band): one workgroup per group writes the band's (count, mean, M2) to
// `stats` at slot·groups + group; group_norm_apply merges the slots of an image.
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> stats: array<f32>;

struct Params {
    hw: u32,
    c: u32,
    groups: u32,
    slot: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let cg = p.c / p.groups;
    let count = p.hw * cg;
    let m = group_moments(wg.x * cg, count, cg, p.c, lid);
    if lid == 0u {
        let at = (p.slot * p.groups + wg.x) * 3u;
        stats[at] = f32(count);
        stats[at + 1u] = m.x;
        stats[at + 2u] = m.y;
    }
}
