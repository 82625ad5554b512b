// The CPU GEMM's turns (gemm_sg.wgsl) read a step of 4 along K at a time: A by `load_a` (from
// storage, or from texels: a_texels.wgsl), B by `b_at` (b_units.wgsl, or b_texels.wgsl where
// TB = 1).

// Rows k..k+3 of B at columns n..n+7, as [2·row + half]. Rows past K are clamped to real
// ones: the A values they meet are zero.
fn load_b(boff: u32, k_in: u32, n: u32) -> array<vec4<f32>, 8> {
    let k = min(k_in, p.g.k - 4u);
    var r: array<vec4<f32>, 8>;
    if BT == 0u {
        let n0 = min(n, p.g.n - 4u);
        let n1 = min(n + 4u, p.g.n - 4u);
        // #unroll I 4
        r[2u * I] = b_at((boff + (k + I) * p.g.ldb + n0) / 4u);
        r[2u * I + 1u] = b_at((boff + (k + I) * p.g.ldb + n1) / 4u);
        // #end
    } else {
        var col: array<vec4<f32>, 8>;
        // #unroll J 8
        col[J] = b_at((boff + b_row(min(n + J, p.g.n - 1u)) * p.g.ldb + k) / 4u);
        // #end
        // #unroll I 4
        r[2u * I] = vec4<f32>(col[0][I], col[1][I], col[2][I], col[3][I]);
        r[2u * I + 1u] = vec4<f32>(col[4][I], col[5][I], col[6][I], col[7][I]);
        // #end
    }
    return r;
}

// The turn from K column k: steps past K read clamped B against zero A.
fn load_turn(rows: array<RowCtx, AU>, boff: u32, k: u32, n: u32) -> Turn {
    var t: Turn;
    // #unroll S KS
    {
        let kc = k_ctx(min(k + 4u * S, p.g.k - 4u));
        // #unroll J AU
        t.a[S][J] = select(vec4<f32>(0.0), load_a(rows[J], kc), k + 4u * S < p.g.k);
        // #end
        t.b[S] = load_b(boff, k + 4u * S, n);
    }
    // #end
    return t;
}
