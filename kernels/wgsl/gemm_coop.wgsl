// GEMM core on the device's matrix units (VK_KHR_cooperative_matrix): f16 operands, f32
// accumulation. A workgroup is 4 subgroups of SG lanes in a 2×2 grid, each computing WT×WT
// fragments of CM×CM (the prelude's FA, FB, FC types), so a workgroup's tile is BM×BM with
// BM = 2·WT·CM. A and B are staged through workgroup memory as f16, read k-fastest where their
// rows run along K (tails and convolution padding read zero, so any M, N, K and strides work).
// Each fragment leaves through a small per-subgroup scratch, so the epilogue and the edge masks
// are those of the scalar kernels (gemm_store.wgsl). Row strides are multiples of 8 halves (16
// bytes, what cooperative loads need), padded off a power of two against bank conflicts.
@group(0) @binding(1) var<storage, read> b: array<S>;

const BM: u32 = 2u * WT * CM;
const BK: u32 = 2u * CM;
const WG: u32 = 4u * SG;
const LDA: u32 = BK + 8u; // A tile [BM][LDA]; B tile [BM][LDA] (BT = 1) or [BK][LDB] (BT = 0)
const LDB: u32 = BM + 8u;
const LDS: u32 = CM + 4u; // a subgroup's f32 scratch [CM][LDS]
// Staged elements per invocation (WT·CM²/SG, the unroll count below), and the tile rows between
// them (WG is a multiple of BK in every variant).
const PER: u32 = BM * BK / WG;
const STEP: u32 = WG / BK;

var<workgroup> a_tile: array<f16, BM * LDA>;
var<workgroup> b_tile: array<f16, max(BM * LDA, BK * LDB)>;
var<workgroup> scratch: array<f32, 4u * CM * LDS>;

fn load_b16(boff: u32, k: u32, n: u32) -> f16 {
    if k >= p.g.k || n >= p.g.n {
        return 0.0h;
    }
    if BT == 0u {
        return f16(b[boff + k * p.g.ldb + n]);
    }
    return f16(b[boff + n * p.g.ldb + k]);
}

@compute @workgroup_size(WG)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(subgroup_id) sid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let row0 = wg.y * BM;
    let col0 = wg.x * BM;
    let batch = wg.z;
    let boff = batch * p.g.b_batch;
    // This subgroup's fragments start at row sm, column sn of the tile.
    let sm = (sid / 2u) * WT * CM;
    let sn = (sid % 2u) * WT * CM;
    // This invocation stages k = k0 + tk of tile rows tr + STEP·i (A, and B when BT = 1).
    let tk = t % BK;
    let tr = t / BK;
    var rows: array<RowCtx, PER>;
    // #unroll I WT*CM*CM/SG
    rows[I] = row_ctx(batch, row0 + tr + STEP * I);
    // #end
    var acc: array<FC, WT * WT>;
    for (var k0 = 0u; k0 < p.g.k; k0 += BK) {
        let ka = k0 + tk;
        let kc = k_ctx(ka);
        // #unroll I WT*CM*CM/SG
        a_tile[(tr + STEP * I) * LDA + tk] = f16(select(0.0, load_a1(rows[I], kc), ka < p.g.k));
        if BT == 1u {
            b_tile[(tr + STEP * I) * LDA + tk] = load_b16(boff, ka, col0 + tr + STEP * I);
        } else {
            let at = t + WG * I;
            b_tile[(at / BM) * LDB + at % BM] = load_b16(boff, k0 + at / BM, col0 + at % BM);
        }
        // #end
        workgroupBarrier();
        // #unroll KK 2
        {
            var fa: array<FA, WT>;
            var fb: array<FB, WT>;
            // #unroll I WT
            {
                // Offsets bound to a `let`: naga 30's SPIR-V output panics on inline ones here.
                let at = (sm + I * CM) * LDA + KK * CM;
                fa[I] = coopLoadT<FA>(&a_tile[at], LDA);
                if BT == 1u {
                    let bt = (sn + I * CM) * LDA + KK * CM;
                    fb[I] = coopLoad<FB>(&b_tile[bt], LDA);
                } else {
                    let bt = KK * CM * LDB + sn + I * CM;
                    fb[I] = coopLoadT<FB>(&b_tile[bt], LDB);
                }
            }
            // #end
            // #unroll I WT
            // #unroll J WT
            acc[WT * I + J] = coopMultiplyAdd(fa[I], fb[J], acc[WT * I + J]);
            // #end
            // #end
        }
        // #end
        workgroupBarrier();
    }
    // One fragment at a time through this subgroup's scratch; every subgroup takes the same
    // number of steps, so the workgroup barriers between them are uniform.
    let own = sid * CM * LDS;
    // #unroll I WT
    // #unroll J WT
    {
        coopStoreT(acc[WT * I + J], &scratch[own], LDS);
        workgroupBarrier();
        for (var e = lane; e < CM * CM; e += SG) {
            let r = e / CM;
            let col = e % CM;
            store(batch, row0 + sm + I * CM + r, col0 + sn + J * CM + col, scratch[own + r * LDS + col]);
        }
        workgroupBarrier();
    }
    // #end
    // #end
}
