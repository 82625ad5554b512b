// Fused multi-head attention on the device's matrix units (VK_KHR_cooperative_matrix), heads of
// up to DH values: a workgroup of 4 subgroups takes 4·CM query rows of one head, CM rows per
// subgroup. Per chunk of KC keys, staged with their values in workgroup memory as f16, each
// subgroup computes its scores S = (scale·Q)·Kᵀ on the matrix units (f32 accumulation), one
// lane per row runs the online softmax over them (writing P as f16 and rescaling the row's
// output), and the matrix units add P·V into the output rows, which stay in workgroup memory
// as f32 because the rescaling is per row. The first chunk holds key 0, which no mask hides, so
// each row's maximum is finite from then on. Operands and parameters: attention_common.wgsl.
const KC: u32 = 2u * CM; // keys per chunk
const ROWS: u32 = 4u * CM; // query rows per workgroup (= 2·KC: Q is staged where K and V go)
const WG: u32 = 4u * SG;
const SLOTS: u32 = DH / 4u;
const NB: u32 = DH / CM; // fragments along a head
// Row strides: f16 ones multiples of 8 (16 bytes, what cooperative loads need), f32 ones of 4,
// padded off a power of two against bank conflicts.
const LD: u32 = DH + 8u; // Q, K and V rows (f16)
const LS: u32 = KC + 4u; // scores (f32)
const LP: u32 = KC + 8u; // probabilities (f16)
const LO: u32 = DH + 4u; // output rows (f32)

var<workgroup> kv: array<f16, 2u * KC * LD>; // a chunk's K rows, then its V rows
var<workgroup> scores: array<f32, ROWS * LS>;
var<workgroup> probs: array<f16, ROWS * LP>;
var<workgroup> out_rows: array<f32, ROWS * LO>;
var<workgroup> row_max: array<f32, ROWS>;
var<workgroup> row_sum: array<f32, ROWS>;

fn put(at: u32, x: vec4<f32>) {
    kv[at] = f16(x.x);
    kv[at + 1u] = f16(x.y);
    kv[at + 2u] = f16(x.z);
    kv[at + 3u] = f16(x.w);
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
    // This subgroup's rows start at `mine` in the workgroup's tile.
    let mine = sid * CM;
    // Scaled Q rows through `kv` (rows past the end clamped, slots past the head zero).
    for (var i = t; i < ROWS * SLOTS; i += WG) {
        let r = i / SLOTS;
        let s = i % SLOTS;
        let token = min(row0 + r, p.nq - 1u);
        let at = (p.q_off + batch * p.q_batch + token * p.q_ld + head * p.d) / 4u + min(s, slots - 1u);
        put(r * LD + 4u * s, select(vec4<f32>(0.0), p.scale * vec4<f32>(q[at]), s < slots));
    }
    if t < ROWS {
        row_max[t] = NEG;
    }
    workgroupBarrier();
    var qf: array<FA, NB>;
    // #unroll B DH/CM
    {
        let at = mine * LD + B * CM;
        qf[B] = coopLoadT<FA>(&kv[at], LD);
    }
    // #end
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
        // #unroll J 2
        {
            var sf: FC;
            // #unroll B DH/CM
            {
                let at = J * CM * LD + B * CM;
                sf = coopMultiplyAdd(qf[B], coopLoad<FB>(&kv[at], LD), sf);
            }
            // #end
            let st = mine * LS + J * CM;
            coopStoreT(sf, &scores[st], LS);
        }
        // #end
        workgroupBarrier();
        for (var r = mine + lane; r < mine + CM; r += SG) {
            let query = row0 + r;
            var top = row_max[r];
            for (var j = 0u; j < KC; j++) {
                let key = j0 + j;
                let s = select(NEG, scores[r * LS + j], key < p.nk && (p.causal == 0u || key <= query));
                scores[r * LS + j] = s;
                top = max(top, s);
            }
            let correction = exp(row_max[r] - top);
            var sum = 0.0;
            for (var j = 0u; j < KC; j++) {
                // The weights P·V uses: rounded to f16, summed as rounded.
                let w = f16(exp(scores[r * LS + j] - top));
                probs[r * LP + j] = w;
                sum += f32(w);
            }
            row_sum[r] = row_sum[r] * correction + sum;
            row_max[r] = top;
            for (var d = 0u; d < DH; d++) {
                out_rows[r * LO + d] *= correction;
            }
        }
        workgroupBarrier();
        // O += P·V, one fragment of the head at a time.
        // #unroll B DH/CM
        {
            let ot = mine * LO + B * CM;
            var acc = coopLoadT<FC>(&out_rows[ot], LO);
            // #unroll J 2
            {
                let pt = mine * LP + J * CM;
                let vt = (KC + J * CM) * LD + B * CM;
                acc = coopMultiplyAdd(coopLoadT<FA>(&probs[pt], LP), coopLoadT<FB>(&kv[vt], LD), acc);
            }
            // #end
            coopStoreT(acc, &out_rows[ot], LO);
        }
        // #end
        // Every subgroup is done with the chunk (and its output rows) before the next one.
        workgroupBarrier();
    }
    for (var i = lane; i < CM * SLOTS; i += SG) {
        let r = mine + i / SLOTS;
        let s = i % SLOTS;
        let query = row0 + r;
        if query < p.nq && s < slots {
            let at = r * LO + 4u * s;
            let x = vec4<f32>(out_rows[at], out_rows[at + 1u], out_rows[at + 2u], out_rows[at + 3u]) / row_sum[r];
            o[(batch * p.o_batch + query * p.o_ld + head * p.d) / 4u + s] = vec4<S>(x);
        }
    }
}
