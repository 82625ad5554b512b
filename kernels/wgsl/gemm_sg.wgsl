// GEMM core for CPU-like devices (lavapipe), after a kernel study on lavapipe: a workgroup is one subgroup of
// SG lanes; each lane owns 8 consecutive output columns for TM rows and reads AU = TM / SG of
// those rows' A (at least one) as vec4 along K, which subgroup broadcasts from constant lanes
// hand to the others, so no shared memory and few loads per product. Lavapipe splits every fma
// into a multiply and an add, so a step adds its four products to a row's sums at once, not by
// four fmas (1.1× in f32).
// Needs N, K and every stride to be multiples of 4. B is K×N (BT = 0) or N×K (BT = 1); each turn's
// A and B come from `load_turn` (gemm_sg_steps.wgsl, or gemm_sg_pairs.wgsl).

const GB: u32 = 4u; // GEGLU blocks (gemm_common.wgsl): a lane's 8 columns are 4 values, 4 gates

// A and B of one turn: KS steps of 4 along K, as [step][A row slot or B half-row] (load_turn:
// gemm_sg_steps.wgsl a step at a time, gemm_sg_pairs.wgsl two steps a texel).
struct Turn {
    a: array<array<vec4<f32>, AU>, KS>,
    b: array<array<vec4<f32>, 8>, KS>,
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
    // (docs/benchmark-log.md); the 8-row variants take one, for short compiles.
    for (var k = 0u; k < p.g.k; k += 4u * KS) {
        let t = load_turn(rows, boff, k, n);
        // #unroll R TM
        {
            var s0 = acc[2u * R];
            var s1 = acc[2u * R + 1u];
            // #unroll S KS
            {
                let x = subgroupBroadcast(t.a[S][R / SG], R % SG);
                s0 += (x.x * t.b[S][0] + x.y * t.b[S][2]) + (x.z * t.b[S][4] + x.w * t.b[S][6]);
                s1 += (x.x * t.b[S][1] + x.y * t.b[S][3]) + (x.z * t.b[S][5] + x.w * t.b[S][7]);
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
