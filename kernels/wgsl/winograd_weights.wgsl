// Winograd F(2×2, 3×3), the filters (runtime ops/winograd.rs): each invocation takes one 3×3
// filter [Cout, 3, 3, Cin] at four input channels and writes G·g·Gᵀ, its 16 transformed values,
// one per plane of u [16][Cout][Cin]. Counts are in units of four channels (unit_4.wgsl).
@group(0) @binding(0) var<storage, read> g: array<U>;
@group(0) @binding(1) var<storage, read_write> u: array<U>;

struct Params {
    n: u32,
    c: u32,
    groups_x: u32,
}

var<immediate> p: Params;

// G·(a, b, c): G = the F(2, 3) filter transform.
fn filter_rows(a: vec4<f32>, b: vec4<f32>, c: vec4<f32>) -> array<vec4<f32>, 4> {
    return array<vec4<f32>, 4>(a, 0.5 * (a + b + c), 0.5 * (a - b + c), c);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let ch = i % p.c;
    let o = i / p.c;
    var t: array<vec4<f32>, 12>;
    for (var s = 0u; s < 3u; s++) {
        let at = (o * 9u + s) * p.c + ch;
        let col = filter_rows(widen(g[at]), widen(g[at + 3u * p.c]), widen(g[at + 6u * p.c]));
        for (var r = 0u; r < 4u; r++) {
            t[3u * r + s] = col[r];
        }
    }
    for (var r = 0u; r < 4u; r++) {
        let out = filter_rows(t[3u * r], t[3u * r + 1u], t[3u * r + 2u]);
        for (var s = 0u; s < 4u; s++) {
            u[(4u * r + s) * p.n + i] = narrow(out[s]);
        }
    }
}
