// GEMM core for CPU-like devices (lavapipe), after a kernel study on lavapipe: a workgroup is one subgroup of
// SG lanes; each lane owns 8 consecutive output columns for TM rows, reads A once as vec4 along K
// and hands it to the other lanes by subgroup shuffles, so no shared memory and few loads per FMA.
// The loop over the lanes whose A is shared stays rolled in the 8-row variants (LU = 1, for
// quick compiles): a shuffle from a varying lane, which took Mesa 25's JIT 14 s instead of 34 s
// at 16 rows. The others unroll it (LU = SG), a broadcast from a constant lane: rolled, the
// networks' tests ran 1.6× slower at 16 lanes.
// Needs N, K and every stride to be multiples of 4. B is K×N (BT = 0) or N×K (BT = 1).
@group(0) @binding(1) var<storage, read> b: array<Unit>;

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
        r[2u * I] = unit_f32(b[(boff + (k + I) * p.g.ldb + n0) / 4u]);
        r[2u * I + 1u] = unit_f32(b[(boff + (k + I) * p.g.ldb + n1) / 4u]);
        // #end
    } else {
        var col: array<vec4<f32>, 8>;
        // #unroll J 8
        col[J] = unit_f32(b[(boff + b_row(min(n + J, p.g.n - 1u)) * p.g.ldb + k) / 4u]);
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
    var rows: array<RowCtx, TM>;
    // #unroll R TM
    rows[R] = row_ctx(batch, row0 + R);
    // #end
    var acc: array<vec4<f32>, 2u * TM>;
    for (var k0 = 0u; k0 < p.g.k; k0 += 4u * SG) {
        // The last chunk may run past K: those lanes hold zeros, so no step needs a branch
        // (llvmpipe masks every branch, which costs more than the wasted FMAs).
        let ka = k0 + 4u * lane;
        let kc = k_ctx(ka);
        var av: array<vec4<f32>, TM>;
        // #unroll R TM
        av[R] = select(vec4<f32>(0.0), load_a(rows[R], kc), ka < p.g.k);
        // #end
        if LU == 1u {
            for (var source = 0u; source < SG; source++) {
                let bv = load_b(boff, k0 + 4u * source, n);
                // #unroll R TM
                {
                    let x = subgroupShuffle(av[R], source);
                    acc[2u * R] += x.x * bv[0] + x.y * bv[2] + x.z * bv[4] + x.w * bv[6];
                    acc[2u * R + 1u] += x.x * bv[1] + x.y * bv[3] + x.z * bv[5] + x.w * bv[7];
                }
                // #end
            }
        } else {
            // Four source lanes' B values (16 rows of K) first, then each row's sums over them: a
            // row's sums stay in registers for 32 products while the B values are read back from
            // the stack (LLVM spills them once), where B loads between the products spilled every
            // sum at each one (docs/benchmark-log.md, 2026-12-05: 2.3× on Mesa 26.1 in f16). A
            // whole chunk's B at 16 lanes spilled too much: four lanes at a time at every width.
            // #unroll G SG/4
            {
                var bv: array<array<vec4<f32>, 8>, 4>;
                // #unroll L 4
                bv[L] = load_b(boff, k0 + 4u * (4u * G + L), n);
                // #end
                // #unroll R TM
                {
                    var s0 = acc[2u * R];
                    var s1 = acc[2u * R + 1u];
                    // #unroll L 4
                    {
                        let x = subgroupBroadcast(av[R], 4u * G + L);
                        // #unroll C 4
                        s0 = fma(vec4<f32>(x[C]), bv[L][2u * C], s0);
                        s1 = fma(vec4<f32>(x[C]), bv[L][2u * C + 1u], s1);
                        // #end
                    }
                    // #end
                    acc[2u * R] = s0;
                    acc[2u * R + 1u] = s1;
                }
                // #end
            }
            // #end
        }
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
