// The CPU GEMM's turns (gemm_sg.wgsl) for f16 A and B (B stored N×K), both read from uniform
// texel buffers of eight halves a texel (RGBA32UI), so that one fetch holds two steps along K
// (TA = 1, KS even). Lavapipe before Mesa 26 fetches a texel for all lanes at once, where it
// loads storage in a loop of branches over the lanes; 16-byte texels halve the fetches of
// RGBA16F ones. K and every row and batch stride are multiples of 8 (the runtime checks).
// WGSL has no texel buffers: the build declares these 1D textures as ones (spirv_texels.rs).
@group(0) @binding(0) var a: texture_1d<u32>;
@group(0) @binding(1) var b: texture_1d<u32>;

const A_VEC: u32 = 8u;

// Eight halves as two vec4s of f32.
fn halves(t: vec4<u32>) -> array<vec4<f32>, 2> {
    let lo = vec4<f32>(unpack2x16float(t.x), unpack2x16float(t.y));
    return array<vec4<f32>, 2>(lo, vec4<f32>(unpack2x16float(t.z), unpack2x16float(t.w)));
}

// The turn from K column k, a pair of steps a fetch: pairs past K read clamped texels against
// zero A.
fn load_turn(rows: array<RowCtx, AU>, boff: u32, k: u32, n: u32) -> Turn {
    var t: Turn;
    // #unroll P KS/2
    {
        let inside = k + 8u * P < p.g.k;
        let kc = k_ctx(k + 8u * P);
        // #unroll J AU
        {
            let h = halves(textureLoad(a, i32((rows[J] + kc) / 8u), 0));
            t.a[2u * P][J] = select(vec4<f32>(0.0), h[0], inside);
            t.a[2u * P + 1u][J] = select(vec4<f32>(0.0), h[1], inside);
        }
        // #end
        var col: array<array<vec4<f32>, 2>, 8>;
        // #unroll J 8
        col[J] = halves(textureLoad(b, i32((boff + b_row(min(n + J, p.g.n - 1u)) * p.g.ldb + kc) / 8u), 0));
        // #end
        // #unroll H 2
        // #unroll I 4
        t.b[2u * P + H][2u * I] = vec4<f32>(col[0][H][I], col[1][H][I], col[2][H][I], col[3][H][I]);
        t.b[2u * P + H][2u * I + 1u] = vec4<f32>(col[4][H][I], col[5][H][I], col[6][H][I], col[7][H][I]);
        // #end
        // #end
    }
    // #end
    return t;
}
