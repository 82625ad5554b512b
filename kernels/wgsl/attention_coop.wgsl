// Fused multi-head attention on the device's matrix units (VK_KHR_cooperative_matrix), heads of
// up to DH values: a workgroup of 4 subgroups takes 4·FM query rows of one head, FM rows per
// subgroup, with the rows' Q fragments and output accumulators held in the matrix registers.
// Fragments are the prelude's: Q·Kᵀ takes Q as FM×FK A fragments along the head and Kᵀ as
// FK×FN B fragments along the keys; P·V takes P as FM×FK A fragments along the keys and V as
// FK×FN B fragments along the head. Per chunk of KC = KF·FN keys, staged with their values in workgroup memory as f16 (loaded
// into registers while the chunk before is computed, so the loads' latency hides), each
// subgroup computes its scores S = (scale·Q)·Kᵀ into its own scratch (f32 accumulation; the
// scale is folded into Q before its rounding to f16, exact for SDXL's 1/8). LPR lanes share a
// row and run its online softmax in base 2 over the scores held in registers, joined by
// shuffles, writing P as f16, SG/LPR rows at a time (on GPUs LPR = SG/FM: every lane in one
// pass; lavapipe's variants take two passes of LPR = 2, so CI runs the joined softmax that GPUs
// do); the matrix units then add P·V to the accumulators. The powers are taken against a
// per-row reference that moves only when a chunk's maximum passes it by more than LAZY, so P
// stays under 2^LAZY (well inside f16) and
// the accumulators are rescaled (a pass through workgroup memory) only on the rare chunk that
// moves one; the first chunk holds key 0, which no mask hides, so every reference is finite
// from then on. Workgroup memory is held as vec4s (four f16 or f32 per access; cooperative
// loads and stores then count strides in vec4s), and a lane's keys in the softmax are
// contiguous, so each of its shared accesses moves four values. Operands: attention_common.wgsl;
// their staging: attention_staging.wgsl.
const KC: u32 = KF * FN; // keys per chunk (a multiple of FK)
const ROWS: u32 = 4u * FM; // query rows per workgroup (≤ 2·KC: Q is staged where K and V go)
const WG: u32 = 4u * SG;
const_assert PU == KC * SLOTS / WG; // a chunk's K (and V) units per invocation
const SLOTS: u32 = DH / 4u;
const NB: u32 = DH / FN; // output fragments along a head
const RPP: u32 = SG / LPR; // rows per pass of the softmax (LPR lanes a row; RPP divides FM)
const PK: u32 = KC / LPR; // a lane's keys per chunk, PK/4 vec4s (the `#unroll I KF*FN/LPR/4`)
const LAZY: f32 = 11.0;
const LOG2E: f32 = 1.4426950408889634;
// Row strides: f16 ones multiples of 8 (16 bytes, what cooperative loads need), f32 ones of 4,
// padded off a power of two against bank conflicts.
const LD: u32 = DH + 8u; // Q, K and V rows (f16)
const LS: u32 = max(KC, DH) + 4u; // a subgroup's scratch rows (f32): scores, or output rows
const LP: u32 = KC + 8u; // probabilities (f16)

var<workgroup> kv: array<Words, 2u * KC * LD / 4u>; // a chunk's K rows, then its V rows
var<workgroup> scratch: array<vec4<f32>, ROWS * LS / 4u>;
var<workgroup> probs: array<Words, ROWS * LP / 4u>;
var<workgroup> row_ref: array<f32, ROWS>;
var<workgroup> row_sum: array<f32, ROWS>;
var<workgroup> row_scale: array<f32, ROWS>;
var<workgroup> moved: array<u32, 4>; // per subgroup: a reference moved in this chunk

fn joined_max(x: f32) -> f32 {
    var m = x;
    for (var s = 1u; s < LPR; s <<= 1u) {
        m = max(m, subgroupShuffleXor(m, s));
    }
    return m;
}

fn joined_sum(x: f32) -> f32 {
    var m = x;
    for (var s = 1u; s < LPR; s <<= 1u) {
        m += subgroupShuffleXor(m, s);
    }
    return m;
}

// Keys j..j+3 of row `row` (of the workgroup) in this chunk: their scores, or NEG where masked
// (past the keys' end, or after the query under a causal mask) if the chunk is `masked`.
fn scores(row: u32, query: u32, j0: u32, j: u32, masked: bool) -> vec4<f32> {
    let key = vec4<u32>(j0 + j) + vec4<u32>(0u, 1u, 2u, 3u);
    let live = key < vec4<u32>(p.nk) & (vec4<bool>(p.causal == 0u) | key <= vec4<u32>(query));
    return select(vec4<f32>(NEG), scratch[row * (LS / 4u) + j / 4u], !vec4<bool>(masked) | live);
}

fn max4(x: vec4<f32>) -> f32 {
    return max(max(x.x, x.y), max(x.z, x.w));
}

@compute @workgroup_size(WG)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(subgroup_id) sid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
) {
    let head = wg.y;
    let batch = wg.z;
    let row0 = wg.x * ROWS;
    let slots = p.d / 4u;
    // This subgroup's rows start at `mine` in the workgroup's tile (and in `scratch`).
    let mine = sid * FM;
    let part = lane % LPR;
    // The first chunk's keys and values are loaded while Q is staged.
    var rk: array<Unit, PU>;
    var rv: array<Unit, PU>;
    fetch_kv(&rk, &rv, 0u, t, head, batch);
    stage_q(row0, head, batch, t);
    if t < ROWS {
        row_ref[t] = NEG;
        row_sum[t] = 0.0;
    }
    workgroupBarrier();
    var qf: array<FA, DH / FK>;
    // #unroll B DH/FK
    {
        let at = mine * (LD / 4u) + B * FK / 4u;
        qf[B] = coopLoadT<FA>(&kv[at], LD / 4u);
    }
    // #end
    var acc: array<FC, NB>;
    workgroupBarrier();
    for (var j0 = 0u; j0 < p.nk; j0 += KC) {
        store_kv(&rk, &rv, t);
        workgroupBarrier();
        // Unconditional (the last chunk's fetch reads clamped keys, never used): a branch
        // around it made AMD's compiler wait for the loads at its end.
        fetch_kv(&rk, &rv, j0 + KC, t, head, batch);
        // S = Q·Kᵀ: K rows [key][d] read column-major are Kᵀ.
        // #unroll J KF
        {
            var sf: FC;
            // #unroll B DH/FK
            {
                let at = (J * FN * LD + B * FK) / 4u;
                sf = coopMultiplyAdd(qf[B], coopLoad<FB>(&kv[at], LD / 4u), sf);
            }
            // #end
            let st = mine * (LS / 4u) + J * FN / 4u;
            coopStoreT(sf, &scratch[st], LS / 4u);
        }
        // #end
        // The scores are this subgroup's rows, read by its own lanes only.
        subgroupBarrier();
        // The softmax of this subgroup's rows, RPP rows at a time. Only a chunk past the keys'
        // end or under a causal mask masks scores: each select is one more instruction a step.
        let masked = (j0 + KC > p.nk) | (p.causal != 0u);
        var any_moved = false;
        for (var r0 = 0u; r0 < FM; r0 += RPP) {
            let row = mine + r0 + lane / LPR;
            var moved_here: bool;
            if masked {
                moved_here = chunk_softmax(row, row0, j0, part, true);
            } else {
                moved_here = chunk_softmax(row, row0, j0, part, false);
            }
            any_moved = any_moved | moved_here;
        }
        let sub_moved = subgroupAny(any_moved);
        if lane == 0u {
            moved[sid] = u32(sub_moved);
        }
        // Also the barrier that makes P and the row scales visible.
        let m = workgroupUniformLoad(&moved);
        if (m[0] | m[1] | m[2] | m[3]) != 0u {
            rescale(&acc, mine, lane);
        }
        // O += P·V, one fragment of the head at a time.
        var pf: array<FA, KC / FK>;
        // #unroll J KF*FN/FK
        {
            let pt = mine * (LP / 4u) + J * FK / 4u;
            pf[J] = coopLoadT<FA>(&probs[pt], LP / 4u);
        }
        // #end
        // #unroll B DH/FN
        // #unroll J KF*FN/FK
        {
            let vt = ((KC + J * FK) * LD + B * FN) / 4u;
            acc[B] = coopMultiplyAdd(pf[J], coopLoadT<FB>(&kv[vt], LD / 4u), acc[B]);
        }
        // #end
        // #end
        // Every subgroup is done with the chunk before the next one is staged.
        workgroupBarrier();
    }
    // The output rows through this subgroup's scratch, divided by their sums.
    // #unroll B DH/FN
    {
        let ot = mine * (LS / 4u) + B * FN / 4u;
        coopStoreT(acc[B], &scratch[ot], LS / 4u);
    }
    // #end
    subgroupBarrier();
    for (var i = lane; i < FM * SLOTS; i += SG) {
        let r = mine + i / SLOTS;
        let s = i % SLOTS;
        let query = row0 + r;
        if (query < p.nq) & (s < slots) {
            let x = scratch[r * (LS / 4u) + s] / row_sum[r];
            o[(batch * p.o_batch + query * p.o_ld + head * p.d) / 4u + s] = narrow(x);
        }
    }
}

// The online softmax of row `row` over this chunk, this lane taking keys part·PK .. part·PK + PK
// (joined with the row's other lanes by shuffles): writes the row's P, sum, reference and
// rescale factor; returns whether its reference moved (and the accumulators need rescaling).
fn chunk_softmax(row: u32, row0: u32, j0: u32, part: u32, masked: bool) -> bool {
    let query = row0 + row;
    let first = part * PK;
    var sv: array<vec4<f32>, PK / 4u>;
    var top = NEG;
    // #unroll I KF*FN/LPR/4
    sv[I] = LOG2E * scores(row, query, j0, first + 4u * I, masked);
    top = max(top, max4(sv[I]));
    // #end
    top = joined_max(top);
    let old = row_ref[row];
    let now = select(old, top, top > old + LAZY);
    var sum = 0.0;
    // #unroll I KF*FN/LPR/4
    {
        // The weights P·V uses: rounded to f16, summed as rounded.
        let w = narrow(exp2(sv[I] - now));
        probs[row * (LP / 4u) + first / 4u + I] = tiled(w);
        sum += dot(widen(w), vec4<f32>(1.0));
    }
    // #end
    sum = joined_sum(sum);
    // exp2(NEG - now) = 0 on the first chunk, whose accumulators are still zero.
    let scale = exp2(old - now);
    if part == 0u {
        row_sum[row] = row_sum[row] * scale + sum;
        row_ref[row] = now;
        row_scale[row] = scale;
    }
    return (now != old) & (old != NEG);
}

// Multiplies each of this subgroup's output rows by its row_scale, through its scratch rows
// (its own: subgroup barriers suffice).
fn rescale(acc: ptr<function, array<FC, NB>>, mine: u32, lane: u32) {
    // #unroll B DH/FN
    {
        let ot = mine * (LS / 4u) + B * FN / 4u;
        coopStoreT((*acc)[B], &scratch[ot], LS / 4u);
    }
    // #end
    subgroupBarrier();
    for (var i = lane; i < FM * SLOTS; i += SG) {
        let r = mine + i / SLOTS;
        scratch[r * (LS / 4u) + i % SLOTS] *= row_scale[r];
    }
    subgroupBarrier();
    // #unroll B DH/FN
    {
        let ot = mine * (LS / 4u) + B * FN / 4u;
        (*acc)[B] = coopLoadT<FC>(&scratch[ot], LS / 4u);
    }
    // #end
}
