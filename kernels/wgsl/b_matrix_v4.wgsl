// B operand read in units of UW values along K (B stored N×K, BT = 1) or along N (K×N, BT = 0);
// K (and N where BT = 0), ldb and b_batch multiples of UW, N of 4 (the runtime picks another
// variant otherwise).
@group(0) @binding(1) var<storage, read> b: array<Unit>;

// The unit at (k, n) of the product's B, as stored, read at (k, n) clamped into B: always in
// bounds, so no branch stands around the load (NAK, Mesa's NVIDIA compiler, put two nested
// branches around each one). Units past K and N are B's last ones: b_unit_inside tells them
// apart, and the kernels apply it only when they store the unit, so that nothing waits for the
// load before then.
fn b_unit(boff: u32, k: u32, n: u32) -> Unit {
    if BT == 0u {
        return b[(boff + min(k, p.g.k - 1u) * p.g.ldb + min(n, p.g.n - UW)) / UW];
    }
    return b[(boff + b_row(min(n, p.g.n - 1u)) * p.g.ldb + min(k, p.g.k - UW)) / UW];
}

fn b_unit_inside(k: u32, n: u32) -> bool {
    return (k < p.g.k) & (n < p.g.n);
}
