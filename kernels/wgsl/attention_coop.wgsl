// Fused multi-head attention on the device's matrix units (VK_KHR_cooperative_matrix), heads of
// up to DH values: a workgroup of 4 subgroups takes 4·CM query rows of one head, CM rows per
// subgroup, with the rows' Q fragments and output accumulators held in the matrix registers.
// Per chunk of KC = KF·CM keys, staged with their values in workgroup memory as f16, each
// subgroup computes its scores S = (scale·Q)·Kᵀ into its own scratch (f32 accumulation; the
// scale is folded into Q before its rounding to f16, exact for SDXL's 1/8). SG/CM lanes share
// a row (SG ≥ CM in every variant) and run its online softmax in base 2 over the scores held in
// registers, joined by shuffles, writing P as f16; the matrix units then add P·V to the
// accumulators. The powers are taken against a per-row reference that moves only when a
// chunk's maximum passes it by more than LAZY, so P stays under 2^LAZY (well inside f16) and
// the accumulators are rescaled (a pass through workgroup memory) only on the rare chunk that
// moves one; the first chunk holds key 0, which no mask hides, so every reference is finite
// from then on. Operands: attention_common.wgsl.
const KC: u32 = KF * CM; // keys per chunk
const ROWS: u32 = 4u * CM; // query rows per workgroup (≤ 2·KC: Q is staged where K and V go)
const WG: u32 = 4u * SG;
const SLOTS: u32 = DH / 4u;
const NB: u32 = DH / CM; // fragments along a head
const LPR: u32 = SG / CM; // lanes per row in the softmax
const PK: u32 = KC / LPR; // a lane's keys per chunk (the `#unroll I KF*CM*CM/SG` loops)
const LAZY: f32 = 11.0;
const LOG2E: f32 = 1.4426950408889634;
// Row strides: f16 ones multiples of 8 (16 bytes, what cooperative loads need), f32 ones of 4,
// padded off a power of two against bank conflicts.
const LD: u32 = DH + 8u; // Q, K and V rows (f16)
const LS: u32 = max(KC, DH) + 4u; // a subgroup's scratch rows (f32): scores, or output rows
const LP: u32 = KC + 8u; // probabilities (f16)

var<workgroup> kv: array<f16, 2u * KC * LD>; // a chunk's K rows, then its V rows
var<workgroup> scratch: array<f32, ROWS * LS>;
var<workgroup> probs: array<f16, ROWS * LP>;
var<workgroup> row_ref: array<f32, ROWS>;
var<workgroup> row_sum: array<f32, ROWS>;
var<workgroup> row_scale: array<f32, ROWS>;
var<workgroup> moved: array<u32, 4>; // per subgroup: a reference moved in this chunk

fn put(at: u32, x: vec4<f32>) {
    kv[at] = f16(x.x);
    kv[at + 1u] = f16(x.y);
    kv[at + 2u] = f16(x.z);
    kv[at + 3u] = f16(x.w);
}

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

// Key j of row `row` (of the workgroup) in this chunk: its score, or NEG where masked.
fn score(row: u32, query: u32, j0: u32, j: u32) -> f32 {
    let key = j0 + j;
    return select(NEG, scratch[row * LS + j], key < p.nk && (p.causal == 0u || key <= query));
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
    let mine = sid * CM;
    let part = lane % LPR;
    // Scaled Q rows through `kv` (rows past the end clamped, slots past the head zero).
    for (var i = t; i < ROWS * SLOTS; i += WG) {
        let r = i / SLOTS;
        let s = i % SLOTS;
        let token = min(row0 + r, p.nq - 1u);
        let at = (p.q_off + batch * p.q_batch + token * p.q_ld + head * p.d) / 4u + min(s, slots - 1u);
        put(r * LD + 4u * s, select(vec4<f32>(0.0), p.scale * vec4<f32>(q[at]), s < slots));
    }
    if t < ROWS {
        row_ref[t] = NEG;
        row_sum[t] = 0.0;
    }
    workgroupBarrier();
    var qf: array<FA, NB>;
    // #unroll B DH/CM
    {
        let at = mine * LD + B * CM;
        qf[B] = coopLoadT<FA>(&kv[at], LD);
    }
    // #end
    var acc: array<FC, NB>;
    workgroupBarrier();
    for (var j0 = 0u; j0 < p.nk; j0 += KC) {
        for (var i = t; i < KC * SLOTS; i += WG) {
            let r = i / SLOTS;
            let s = i % SLOTS;
            let key = min(j0 + r, p.nk - 1u);
            let sl = min(s, slots - 1u);
            let ka = (p.k_off + batch * p.k_batch + key * p.k_ld + head * p.d) / 4u + sl;
            let va = (p.v_off + batch * p.v_batch + key * p.v_ld + head * p.d) / 4u + sl;
            put(r * LD + 4u * s, select(vec4<f32>(0.0), vec4<f32>(k[ka]), s < slots));
            put((KC + r) * LD + 4u * s, select(vec4<f32>(0.0), vec4<f32>(v[va]), s < slots));
        }
        workgroupBarrier();
        // S = Q·Kᵀ: K rows [key][d] read column-major are Kᵀ.
        // #unroll J KF
        {
            var sf: FC;
            // #unroll B DH/CM
            {
                let at = J * CM * LD + B * CM;
                sf = coopMultiplyAdd(qf[B], coopLoad<FB>(&kv[at], LD), sf);
            }
            // #end
            let st = mine * LS + J * CM;
            coopStoreT(sf, &scratch[st], LS);
        }
        // #end
        workgroupBarrier();
        // The softmax of this lane's row, over keys part, part + LPR, … of the chunk.
        let row = mine + lane / LPR;
        let query = row0 + row;
        var sv: array<f32, PK>;
        var top = NEG;
        // #unroll I KF*CM*CM/SG
        sv[I] = LOG2E * score(row, query, j0, part + LPR * I);
        top = max(top, sv[I]);
        // #end
        top = joined_max(top);
        let old = row_ref[row];
        let now = select(old, top, top > old + LAZY);
        var sum = 0.0;
        // #unroll I KF*CM*CM/SG
        {
            // The weights P·V uses: rounded to f16, summed as rounded.
            let w = f16(exp2(sv[I] - now));
            probs[row * LP + part + LPR * I] = w;
            sum += f32(w);
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
        let any_moved = now != old && old != NEG;
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
        var pf: array<FA, KF>;
        // #unroll J KF
        {
            let pt = mine * LP + J * CM;
            pf[J] = coopLoadT<FA>(&probs[pt], LP);
        }
        // #end
        // #unroll B DH/CM
        // #unroll J KF
        {
            let vt = (KC + J * CM) * LD + B * CM;
            acc[B] = coopMultiplyAdd(pf[J], coopLoadT<FB>(&kv[vt], LD), acc[B]);
        }
        // #end
        // #end
        // Every subgroup is done with the chunk before the next one is staged.
        workgroupBarrier();
    }
    // The output rows through this subgroup's scratch, divided by their sums.
    // #unroll B DH/CM
    {
        let ot = mine * LS + B * CM;
        coopStoreT(acc[B], &scratch[ot], LS);
    }
    // #end
    workgroupBarrier();
    for (var i = lane; i < CM * SLOTS; i += SG) {
        let r = mine + i / SLOTS;
        let s = i % SLOTS;
        let query = row0 + r;
        if query < p.nq && s < slots {
            let at = r * LS + 4u * s;
            let x = vec4<f32>(scratch[at], scratch[at + 1u], scratch[at + 2u], scratch[at + 3u]) / row_sum[r];
            o[(batch * p.o_batch + query * p.o_ld + head * p.d) / 4u + s] = vec4<S>(x);
        }
    }
}

// Multiplies each of this subgroup's output rows by its row_scale, through its scratch rows.
fn rescale(acc: ptr<function, array<FC, NB>>, mine: u32, lane: u32) {
    // #unroll B DH/CM
    {
        let ot = mine * LS + B * CM;
        coopStoreT((*acc)[B], &scratch[ot], LS);
    }
    // #end
    workgroupBarrier();
    for (var i = lane; i < CM * DH; i += SG) {
        let r = mine + i / DH;
        scratch[r * LS + i % DH] *= row_scale[r];
    }
    workgroupBarrier();
    // #unroll B DH/CM
    {
        let ot = mine * LS + B * CM;
        (*acc)[B] = coopLoadT<FC>(&scratch[ot], LS);
    }
    // #end
}
