// GEMM core for CPU-like devices (lavapipe), after a kernel study on lavapipe: a workgroup is one subgroup of
// SG lanes; each lane owns 8 consecutive output columns for TM rows and reads AU = TM / SG of
// those rows' A (at least one) as vec4 along K, which subgroup broadcasts from constant lanes
// hand to the others, so no shared memory and few loads per product. Lavapipe splits every fma
// into a multiply and an add, so a step adds its four products to a row's sums at once, not by
// four fmas (1.1× in f32).
// Needs N, K and every stride to be multiples of 4. B is K×N (BT = 0) or N×K (BT = 1), read by
// `b_at` (b_units.wgsl, or b_texels.wgsl where TB = 1).

const GB: u32 = 4u; // GEGLU blocks (gemm_common.wgsl): a lane's 8 columns are 4 values, 4 gates

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

@compute @workgroup_size(SG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let n = (wg.x * SG + lane) * 8u;
    let row0 = wg.y * TM;
    let batch = wg.z;
    let boff = batch * p.g.b_batch;
    // Lane l reads rows l, l + SG, …: row r's A is lane r % SG's slot r / SG.
    var rows: array<RowCtx, AU>;
    // #unroll J AU
    rows[J] = row_ctx(batch, row0 + J * SG + lane);
    // #end
    var acc: array<vec4<f32>, 2u * TM>;
    // KS steps of 4 along K a turn: every B and A value of the turn first, then each row's sums
    // over them, kept in registers while the values are read back from the stack (LLVM spills
    // them once). Four steps ran fastest: one stores the sums 4× as often; eight ran slower too
    // (docs/benchmark-log.md); the 8-row variants take one, for short compiles. Steps past K read
    // clamped B against zero A.
    for (var k = 0u; k < p.g.k; k += 4u * KS) {
        var av: array<array<vec4<f32>, AU>, KS>;
        var bv: array<array<vec4<f32>, 8>, KS>;
        // #unroll S KS
        {
            let kc = k_ctx(min(k + 4u * S, p.g.k - 4u));
            // #unroll J AU
            av[S][J] = select(vec4<f32>(0.0), load_a(rows[J], kc), k + 4u * S < p.g.k);
            // #end
            bv[S] = load_b(boff, k + 4u * S, n);
        }
        // #end
        // #unroll R TM
        {
            var s0 = acc[2u * R];
            var s1 = acc[2u * R + 1u];
            // #unroll S KS
            {
                let x = subgroupBroadcast(av[S][R / SG], R % SG);
                s0 += (x.x * bv[S][0] + x.y * bv[S][2]) + (x.z * bv[S][4] + x.w * bv[S][6]);
                s1 += (x.x * bv[S][1] + x.y * bv[S][3]) + (x.z * bv[S][5] + x.w * bv[S][7]);
            }
            // #end
            acc[2u * R] = s0;
            acc[2u * R + 1u] = s1;
        }
        // #end
    }
    if GE == 1u {
        // #unroll R TM
        store_geglu4(batch, row0 + R, n, acc[2u * R], acc[2u * R + 1u]);
        // #end
    } else {
        // #unroll R TM
        // #unroll H 2
        store4(batch, row0 + R, n + 4u * H, acc[2u * R + H]);
        // #end
        // #end
    }
}
