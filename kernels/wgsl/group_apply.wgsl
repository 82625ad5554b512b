// Normalises one GroupNorm group's units (laid out as in group_moments; c0 = its first channel
// unit) with its mean and 1/std, then the affine map and optionally SiLU.
fn group_apply(base: u32, count: u32, cg: u32, c: u32, c0: u32, mean: f32, rstd: f32, silu: bool, lid: u32) {
    for (var e = lid; e < count; e += WG) {
        let at = base + (e / cg) * c + e % cg;
        let ch = c0 + e % cg;
        var v = (widen(x[at]) - mean) * rstd * widen(gamma[ch]) + widen(beta[ch]);
        if silu {
            v = v / (1.0 + exp(-v));
        }
        y[at] = narrow(v);
    }
}
