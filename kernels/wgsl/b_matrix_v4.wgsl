// B operand read as units of four values along K (B stored N×K, BT = 1) or along N (K×N,
// BT = 0); N, K, ldb and b_batch multiples of 4 (the runtime picks another variant otherwise).
@group(0) @binding(1) var<storage, read> b: array<vec4<S>>;

// The unit at (k, n) of the product's B, zero past K and N: read at (k, n) clamped into B and
// masked, so that no branch stands around the load (compilers then issue a step's loads
// together; NAK, Mesa's NVIDIA compiler, put two nested branches around each one).
fn b_unit(boff: u32, k: u32, n: u32) -> vec4<S> {
    let inside = (k < p.g.k) & (n < p.g.n);
    var unit: vec4<S>;
    if BT == 0u {
        unit = b[(boff + min(k, p.g.k - 1u) * p.g.ldb + min(n, p.g.n - 4u)) / 4u];
    } else {
        unit = b[(boff + b_row(min(n, p.g.n - 1u)) * p.g.ldb + min(k, p.g.k - 4u)) / 4u];
    }
    return select(vec4<S>(), unit, inside);
}
