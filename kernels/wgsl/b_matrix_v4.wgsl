// B operand read as units of four values along K (B stored N×K, BT = 1) or along N (K×N,
// BT = 0); N, K, ldb and b_batch multiples of 4 (the runtime picks another variant otherwise).
@group(0) @binding(1) var<storage, read> b: array<vec4<S>>;

// The unit at (k, n) of the product's B, zero past K and N.
fn b_unit(boff: u32, k: u32, n: u32) -> vec4<S> {
    if k >= p.g.k || n >= p.g.n {
        return vec4<S>();
    }
    if BT == 0u {
        return b[(boff + k * p.g.ldb + n) / 4u];
    }
    return b[(boff + b_row(n) * p.g.ldb + k) / 4u];
}
