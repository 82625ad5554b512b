// GEMM core on the device's matrix units (VK_KHR_cooperative_matrix): f16 operands, f32
// accumulation. A workgroup is GM·GN subgroups of SG lanes in a GM×GN grid, each computing WM×WN
// fragments of FM×FN (A fragments FM×FK, B fragments FK×FN: the prelude's FA, FB, FC types), so
// a workgroup's tile is BM×BN with BM = GM·WM·FM and BN = GN·WN·FN, over K-steps of BK = KS·FK:
// 2×2 subgroups of 2×2 (or 4×4) fragments, or 8 subgroups with K-steps of two: 2×4 of 4×2
// fragments (the tiles of NVIDIA's own sample and ggml: 128×128 at 16×16×16, each staged byte
// feeding twice the products of a 64×64 tile, with the sums in 64 registers a lane), or 4×2 or
// 2×4 of 2×2 (128×64 and 64×128: a third more products a staged byte than 64×64, in its
// registers a lane).
// Operands are aligned to units of UW = 4 or 8 values (the runtime takes 8 where sizes and
// strides allow, and sends shapes off the vec4 grid to the tiled kernel): each invocation
// stages units of UW f16 along K (A, and B stored N×K) or along N (B stored K×N), one 8- or
// 16-byte load each, zero past M, N and K. The next step's units are loaded into registers while
// the matrix units work on this one, so the loads' latency hides behind the products. For that
// nothing may use a unit before the next step stores it: the loads read in bounds (clamped,
// unconditionally) and the masks wait for the stores. Masked as they arrived, or fetched under
// a branch, they made AMD's compiler wait for every load before the step's first product
// (tools/load_cover.py). The loop is short of instruction slots on GPUs whose matrix units are
// fast (an H200 ran the GEMM 2–2.6× faster with the loads and their arithmetic left out), so a
// step does little besides: the columns walk K by additions (a convolution's taps with no
// division, conv_taps.wgsl) and only a last, partial K-step masks the columns past K. Units
// move as their bits (the prelude's Unit), and the tiles hold them as 32-bit float words (its
// Words; compile.rs says why). Row strides are multiples of 8 halves (16 bytes, what cooperative
// loads need), padded off a power of two against bank conflicts. Each fragment leaves through a
// small per-subgroup scratch, four columns at a time, so the epilogue and the edge masks are
// those of the vec4 subgroup kernel (gemm_store4.wgsl).
const NS: u32 = GM * GN; // subgroups
const BM: u32 = GM * WM * FM;
const BN: u32 = GN * WN * FN;
const GB: u32 = 4u; // GEGLU blocks (gemm_common.wgsl): 4 values, then their 4 gates
const BK: u32 = KS * FK;
const WG: u32 = NS * SG;
const LDA: u32 = BK + 8u; // A tile [BM][LDA]; B tile [BN][LDA] (BT = 1) or [BK][LDB] (BT = 0)
const LDB: u32 = BN + 8u;
const LDS: u32 = FN + 4u; // a subgroup's f32 scratch [FM][LDS]
// Units along a tile row of K, A's and B's units per invocation (the unroll counts below), and
// the tile rows between an invocation's units (WG is a multiple of UK in every variant).
const UK: u32 = BK / UW;
const PA: u32 = BM * BK / (UW * WG); // WM·FM·FK·KS/GN/SG/UW
const PB: u32 = BN * BK / (UW * WG); // WN·FN·FK·KS/SG/GM/UW
const STEP: u32 = WG / UK;
// B stored K×N: units along a tile row of N.
const UN: u32 = BN / UW;

var<workgroup> a_tile: array<Words, BM * LDA / UW>;
var<workgroup> b_tile: array<Words, max(BN * LDA, BK * LDB) / UW>;
var<workgroup> scratch: array<vec4<f32>, NS * FM * LDS / 4u>; // NS subgroups × [FM][LDS] f32

// Where this invocation's B unit i of the K-step at k0 lies in the product, (k, n): B's rows
// alike A's (BT = 1), or units t + WG·i of the [BK][BN] step (BT = 0).
fn b_at(i: u32, k0: u32, t: u32, col0: u32) -> vec2<u32> {
    if BT == 0u {
        let at = t + WG * i;
        return vec2<u32>(k0 + at / UN, col0 + UW * (at % UN));
    }
    return vec2<u32>(k0 + UW * (t % UK), col0 + t / UK + STEP * i);
}

// This invocation's units of the K-step whose columns kc walks (A rows tr + STEP·i at column
// k0 + UW·tu, B's as b_at says), and whether each A unit is inside the operand (a convolution's
// padding is not). Columns past K are masked where the units are staged.
fn fetch(
    rows: ptr<function, array<RowCtx, PA>>,
    ra: ptr<function, array<Unit, PA>>,
    rb: ptr<function, array<Unit, PB>>,
    ia: ptr<function, array<bool, PA>>,
    kc: KCtx,
    k0: u32,
    t: u32,
    col0: u32,
    boff: u32,
) {
    // #unroll I WM*FM*FK*KS/GN/SG/UW
    (*ra)[I] = a_unit((*rows)[I], kc);
    (*ia)[I] = a_unit_inside((*rows)[I], kc);
    // #end
    // #unroll I WN*FN*FK*KS/SG/GM/UW
    {
        let kn = b_at(I, k0, t, col0);
        (*rb)[I] = b_unit(boff, kn.x, kn.y);
    }
    // #end
}

// A unit as a tile holds it: its bits, zero outside the product.
fn staged(unit: Unit, inside: bool) -> Words {
    return bitcast<Words>(select(Unit(), unit, inside));
}

// Stores this invocation's units of the K-step at k0 into the tiles. Only the last step of a K
// that is no multiple of BK (`tail`) masks the columns past K; the others store B as loaded and
// A with its own mask only (a convolution's padding; a matrix has none), since each select is
// one more instruction per word of every unit in every step.
fn stage(
    ra: ptr<function, array<Unit, PA>>,
    rb: ptr<function, array<Unit, PB>>,
    ia: ptr<function, array<bool, PA>>,
    k0: u32,
    t: u32,
    col0: u32,
    tail: bool,
) {
    let tu = t % UK;
    let tr = t / UK;
    let in_k = !tail | (k0 + UW * tu < p.g.k);
    // #unroll I WM*FM*FK*KS/GN/SG/UW
    a_tile[(tr + STEP * I) * (LDA / UW) + tu] = staged((*ra)[I], (*ia)[I] & in_k);
    // #end
    // #unroll I WN*FN*FK*KS/SG/GM/UW
    {
        let kn = b_at(I, k0, t, col0);
        let unit = staged((*rb)[I], !tail | b_unit_inside(kn.x, kn.y));
        if BT == 1u {
            b_tile[(tr + STEP * I) * (LDA / UW) + tu] = unit;
        } else {
            let at = t + WG * I;
            b_tile[(at / UN) * (LDB / UW) + at % UN] = unit;
        }
    }
    // #end
}

@compute @workgroup_size(WG)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(subgroup_id) sid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let row0 = wg.y * BM;
    let col0 = wg.x * BN;
    let batch = wg.z;
    let boff = batch * p.g.b_batch;
    // This subgroup's fragments start at row sm, column sn of the tile.
    let sm = (sid / GN) * WM * FM;
    let sn = (sid % GN) * WN * FN;
    let tu = t % UK;
    let tr = t / UK;
    var rows: array<RowCtx, PA>;
    // #unroll I WM*FM*FK*KS/GN/SG/UW
    rows[I] = row_ctx(batch, row0 + tr + STEP * I);
    // #end
    var ra: array<Unit, PA>;
    var rb: array<Unit, PB>;
    var ia: array<bool, PA>;
    let step = k_step(BK);
    var walk = k_walk(UW * tu);
    fetch(&rows, &ra, &rb, &ia, k_at(walk), 0u, t, col0, boff);
    var acc: array<FC, WM * WN>;
    for (var k0 = 0u; k0 < p.g.k; k0 += BK) {
        if k0 + BK <= p.g.k {
            stage(&ra, &rb, &ia, k0, t, col0, false);
        } else {
            stage(&ra, &rb, &ia, k0, t, col0, true);
        }
        workgroupBarrier();
        walk = k_next(walk, step);
        fetch(&rows, &ra, &rb, &ia, k_at(walk), k0 + BK, t, col0, boff);
        for (var kk = 0u; kk < BK; kk += FK) {
            // B's fragments for the step, then A's one at a time against them: a lane holds
            // WN + 1 operand fragments, not WM + WN.
            var fb: array<FB, WN>;
            // Offsets bound to a `let`: naga 30's SPIR-V output panics on inline ones here. Each
            // a sum of a part fixed for the loop and kk's own, in units (every term is a
            // multiple of UW), so that the compilers fold kk's into the loads' offsets.
            // #unroll J WN
            if BT == 1u {
                let bt = (sn + J * FN) * (LDA / UW) + kk / UW;
                fb[J] = coopLoad<FB>(&b_tile[bt], LDA / UW);
            } else {
                let bt = kk * (LDB / UW) + (sn + J * FN) / UW;
                fb[J] = coopLoadT<FB>(&b_tile[bt], LDB / UW);
            }
            // #end
            // #unroll I WM
            {
                let at = (sm + I * FM) * (LDA / UW) + kk / UW;
                let fa = coopLoadT<FA>(&a_tile[at], LDA / UW);
                // #unroll J WN
                acc[WN * I + J] = coopMultiplyAdd(fa, fb[J], acc[WN * I + J]);
                // #end
            }
            // #end
        }
        workgroupBarrier();
    }
    // One fragment at a time through this subgroup's scratch, which no other subgroup touches:
    // subgroup barriers (the build makes them order workgroup memory) let each subgroup store
    // its tile without waiting for the others at every fragment.
    let own = sid * FM * LDS / 4u;
    // #unroll I WM
    // #unroll J WN
    {
        coopStoreT(acc[WN * I + J], &scratch[own], LDS / 4u);
        subgroupBarrier();
        if GE == 1u {
            for (var e = lane; e < FM * FN / 8u; e += SG) {
                let r = e / (FN / 8u);
                let at = own + r * (LDS / 4u) + 2u * (e % (FN / 8u));
                let col = col0 + sn + J * FN + 8u * (e % (FN / 8u));
                store_geglu4(batch, row0 + sm + I * FM + r, col, scratch[at], scratch[at + 1u]);
            }
        } else {
            for (var e = lane; e < FM * FN / 4u; e += SG) {
                let r = e / (FN / 4u);
                let sum = scratch[own + r * (LDS / 4u) + e % (FN / 4u)];
                store4(batch, row0 + sm + I * FM + r, col0 + sn + J * FN + 4u * (e % (FN / 4u)), sum);
            }
        }
        subgroupBarrier();
    }
    // #end
    // #end
}
