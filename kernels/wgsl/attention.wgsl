// Fused multi-head attention, O = softmax(scale·Q·Kᵀ)·V, streaming over keys with an online
// softmax so no Nq×Nk matrix ever exists. One workgroup = one subgroup of SG lanes handles TM
// query rows of one head. Head slots are vec4s: lane l owns slots v·SG + l (v < DV) of every
// query and output row. For each chunk of SG keys, lane l scores key j0 + l against all TM
// queries (query slots arrive by shuffles), the chunk's softmax statistics are subgroup
// reductions, and each lane accumulates its own output slots from the chunk's V rows.
// Layout: element (b, token, head, d) at b·batch + token·ld + head·D + d; D % 4 = 0.
@group(0) @binding(0) var<storage, read> q: array<vec4<S>>;
@group(0) @binding(1) var<storage, read> k: array<vec4<S>>;
@group(0) @binding(2) var<storage, read> v: array<vec4<S>>;
@group(0) @binding(3) var<storage, read_write> o: array<vec4<S>>;

struct Params {
    nq: u32,
    nk: u32,
    d: u32,
    q_ld: u32,
    k_ld: u32,
    v_ld: u32,
    o_ld: u32,
    q_batch: u32,
    k_batch: u32,
    v_batch: u32,
    o_batch: u32,
    scale: f32,
}

var<immediate> p: Params;

const NEG: f32 = -1.0e30;

@compute @workgroup_size(SG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let head = wg.y;
    let batch = wg.z;
    let row0 = wg.x * TM;
    let slots = p.d / 4u;
    var qs: array<vec4<f32>, TM * DV>;
    var acc: array<vec4<f32>, TM * DV>;
    var m: array<f32, TM>;
    var l: array<f32, TM>;
    for (var r = 0u; r < TM; r++) {
        let base = (batch * p.q_batch + min(row0 + r, p.nq - 1u) * p.q_ld + head * p.d) / 4u;
        for (var s = 0u; s < DV; s++) {
            let slot = s * SG + lane;
            qs[r * DV + s] = select(vec4<f32>(0.0), p.scale * vec4<f32>(q[base + min(slot, slots - 1u)]), slot < slots);
        }
        m[r] = NEG;
    }
    for (var j0 = 0u; j0 < p.nk; j0 += SG) {
        let key = j0 + lane;
        let kbase = (batch * p.k_batch + min(key, p.nk - 1u) * p.k_ld + head * p.d) / 4u;
        var score: array<f32, TM>;
        for (var s = 0u; s < DV; s++) {
            let owners = min(SG, slots - min(slots, s * SG));
            for (var src = 0u; src < owners; src++) {
                let kv = vec4<f32>(k[kbase + s * SG + src]);
                for (var r = 0u; r < TM; r++) {
                    score[r] += dot(subgroupShuffle(qs[r * DV + s], src), kv);
                }
            }
        }
        for (var r = 0u; r < TM; r++) {
            let sc = select(NEG, score[r], key < p.nk);
            let m_new = max(m[r], subgroupMax(sc));
            let correction = exp(m[r] - m_new);
            let pr = exp(sc - m_new);
            l[r] = l[r] * correction + subgroupAdd(pr);
            m[r] = m_new;
            score[r] = pr;
            for (var s = 0u; s < DV; s++) {
                acc[r * DV + s] *= correction;
            }
        }
        let keys = min(SG, p.nk - j0);
        for (var src = 0u; src < keys; src++) {
            let vbase = (batch * p.v_batch + (j0 + src) * p.v_ld + head * p.d) / 4u;
            for (var s = 0u; s < DV; s++) {
                let vv = vec4<f32>(v[vbase + min(s * SG + lane, slots - 1u)]);
                for (var r = 0u; r < TM; r++) {
                    acc[r * DV + s] += subgroupShuffle(score[r], src) * vv;
                }
            }
        }
    }
    for (var r = 0u; r < TM; r++) {
        let row = row0 + r;
        let base = (batch * p.o_batch + row * p.o_ld + head * p.d) / 4u;
        for (var s = 0u; s < DV; s++) {
            let slot = s * SG + lane;
            if row < p.nq && slot < slots {
                o[base + slot] = vec4<S>(acc[r * DV + s] / l[r]);
            }
        }
    }
}
