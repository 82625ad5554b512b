// GroupNorm of bands of pixels (laid out as in group_norm_stats: workgroup (group, part, image))
// from the partial statistics of all bands of the image (slots first + image·parts ..
// + parts, merged with Chan's parallel-variance formula), then the affine map and optional
// SiLU, as group_norm does in one workgroup per group.
@group(0) @binding(0) var<storage, read> x: array<U>;
@group(0) @binding(1) var<storage, read> gamma: array<U>;
@group(0) @binding(2) var<storage, read> beta: array<U>;
@group(0) @binding(3) var<storage, read> stats: array<f32>;
@group(0) @binding(4) var<storage, read_write> y: array<U>;

struct Params {
    hw: u32,
    c: u32,
    groups: u32,
    eps: f32,
    silu: u32,
    first: u32,
    parts: u32,
    band: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let cg = p.c / p.groups;
    let c0 = wg.x * cg;
    let slot0 = p.first + wg.z * p.parts;
    var n = 0.0;
    var mean = 0.0;
    var m2 = 0.0;
    for (var i = 0u; i < p.parts; i++) {
        let at = ((slot0 + i) * p.groups + wg.x) * 3u;
        let nb = stats[at];
        let d = stats[at + 1u] - mean;
        let total = n + nb;
        mean += d * nb / total;
        m2 += stats[at + 2u] + d * d * n * nb / total;
        n = total;
    }
    let first = wg.y * p.band;
    let count = min(p.band, p.hw - first) * cg;
    let base = (wg.z * p.hw + first) * p.c + c0;
    group_apply(base, count, cg, p.c, c0, mean, inverseSqrt(m2 / n + p.eps), p.silu != 0u, lid);
}
