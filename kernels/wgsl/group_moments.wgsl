// Mean and M2 (sum of squared deviations) of one GroupNorm group, two passes in f32 over the
// workgroup: `count` units at x[base + (e / cg) · c + e % cg] (cg units of every pixel; every
// count is in units, unit_1/2/4.wgsl).
fn group_moments(base: u32, count: u32, cg: u32, c: u32, lid: u32) -> vec2<f32> {
    var s = 0.0;
    for (var e = lid; e < count; e += WG) {
        s += total(widen(x[base + (e / cg) * c + e % cg]));
    }
    let mean = workgroup_sum(s, lid) / f32(count * UNIT);
    var q = 0.0;
    for (var e = lid; e < count; e += WG) {
        let d = widen(x[base + (e / cg) * c + e % cg]) - mean;
        q += total(d * d);
    }
    return vec2<f32>(mean, workgroup_sum(q, lid));
}
