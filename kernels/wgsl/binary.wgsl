// out = a op b element-wise with b broadcast: b's index is (i / b_outer)·b_inner + i % b_inner,
// which covers same-shape (b_inner = b_outer = n), a per-channel vector (b_inner = C, b_outer ≥ n)
// and a per-(batch, channel) vector over pixels (b_inner = C, b_outer = H·W·C). OP: 0 add, 1 mul.
// Past the binding limit the runtime binds runs of a and out starting at element `base` of the
// whole tensors, and b's elements from `b_shift` on. Every count is in units (unit_1.wgsl /
// unit_4.wgsl): with b_inner and b_outer multiples of 4, a unit of a meets a unit of b.
@group(0) @binding(0) var<storage, read> a: array<U>;
@group(0) @binding(1) var<storage, read> b: array<U>;
@group(0) @binding(2) var<storage, read_write> out: array<U>;

struct Params {
    n: u32,
    b_inner: u32,
    b_outer: u32,
    base: u32,
    b_shift: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let x = widen(a[i]);
    let g = p.base + i;
    let y = widen(b[(g / p.b_outer) * p.b_inner + g % p.b_inner - p.b_shift]);
    if OP == 0u {
        out[i] = narrow(x + y);
    } else {
        out[i] = narrow(x * y);
    }
}
