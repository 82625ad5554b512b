// Winograd F(2×2, 3×3), step 3 of 3 (runtime ops/winograd.rs): each invocation takes one tile's
// 16 products m [16][tiles][Cout] at four output channels and writes Aᵀ·m·A, the tile's 2×2
// outputs (those inside the output, of h × w pixels), with the convolution's epilogue: + bias,
// + what out holds, ReLU, as gemm_store4.wgsl. Counts are in units of four channels
// (unit_4.wgsl); the tiles are those from `t0` on (winograd_tiles.wgsl).
@group(0) @binding(0) var<storage, read> m: array<U>;
@group(0) @binding(1) var<storage, read> bias: array<U>;
@group(0) @binding(2) var<storage, read_write> out: array<U>;

struct Params {
    n: u32,
    h: u32,
    w: u32,
    c: u32,
    tiles_h: u32,
    tiles_w: u32,
    t0: u32,
    flags: u32,
    plane: u32,
    groups_x: u32,
}

var<immediate> p: Params;

const FLAG_BIAS: u32 = 1u;
const FLAG_ACCUMULATE: u32 = 2u;
const FLAG_RELU: u32 = 4u;

// Aᵀ·(a, b, c, d): A = the F(2, 3) output transform.
fn output_rows(a: vec4<f32>, b: vec4<f32>, c: vec4<f32>, d: vec4<f32>) -> array<vec4<f32>, 2> {
    return array<vec4<f32>, 2>(a + b + c, b - c - d);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let ch = i % p.c;
    let at = tile_at(i);
    let image = at.x;
    let y0 = at.y;
    let x0 = at.z;
    var t: array<vec4<f32>, 8>;
    for (var s = 0u; s < 4u; s++) {
        let col = output_rows(widen(m[s * p.plane + i]), widen(m[(4u + s) * p.plane + i]),
            widen(m[(8u + s) * p.plane + i]), widen(m[(12u + s) * p.plane + i]));
        t[s] = col[0];
        t[4u + s] = col[1];
    }
    var add = vec4<f32>(0.0);
    if (p.flags & FLAG_BIAS) != 0u {
        add = widen(bias[ch]);
    }
    for (var r = 0u; r < 2u; r++) {
        let pair = output_rows(t[4u * r], t[4u * r + 1u], t[4u * r + 2u], t[4u * r + 3u]);
        for (var s = 0u; s < 2u; s++) {
            let y = y0 + r;
            let x = x0 + s;
            if (y < p.h) & (x < p.w) {
                let at = ((image * p.h + y) * p.w + x) * p.c + ch;
                var value = pair[s] + add;
                if (p.flags & FLAG_ACCUMULATE) != 0u {
                    value += widen(out[at]);
                }
                if (p.flags & FLAG_RELU) != 0u {
                    value = max(value, vec4<f32>(0.0));
                }
                out[at] = narrow(value);
            }
        }
    }
}
