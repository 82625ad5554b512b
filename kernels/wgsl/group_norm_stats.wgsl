// GroupNorm statistics of bands of pixels: workgroup (group, part, image) writes the (count,
// mean, M2) of its group over pixels part·band .. part·band + band of its image to `stats` at
// slot (slot + image·parts + part)·groups + group; group_norm_apply merges the slots of an image.
// GPUs split every image so that enough workgroups run; a tensor too large for one binding is
// normalised one band per dispatch.
@group(0) @binding(0) var<storage, read> x: array<U>;
@group(0) @binding(1) var<storage, read_write> stats: array<f32>;

struct Params {
    hw: u32,
    c: u32,
    groups: u32,
    slot: u32,
    band: u32,
    parts: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let cg = p.c / p.groups;
    let first = wg.y * p.band;
    let count = min(p.band, p.hw - first) * cg;
    let m = group_moments((wg.z * p.hw + first) * p.c + wg.x * cg, count, cg, p.c, lid);
    if lid == 0u {
        let at = ((p.slot + wg.z * p.parts + wg.y) * p.groups + wg.x) * 3u;
        stats[at] = f32(count * UNIT);
        stats[at + 1u] = m.x;
        stats[at + 2u] = m.y;
    }
}
