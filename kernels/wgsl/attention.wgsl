// Fused multi-head attention, O = softmax(scale·Q·Kᵀ)·V (optionally causal), streaming over keys with an online
// softmax so no Nq×Nk matrix ever exists. One workgroup = one subgroup of SG lanes handles TM
// query rows of one head. Head slots are vec4s: lane l owns slots v·SG + l (v < DV) of every
// query and output row. For each chunk of SG keys, lane l scores key j0 + l against all TM
// queries (query slots arrive by shuffles), the chunk's softmax statistics are subgroup
// reductions, and each lane accumulates its own output slots from the chunk's V rows.
// Operands, parameters and layout: attention_common.wgsl.

@compute @workgroup_size(SG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let head = wg.y;
    let batch = wg.z;
    let row0 = wg.x * TM;
    let slots = p.d / 4u;
    let last = slots - 1u;
    var qs: array<vec4<f32>, TM * DV>;
    var acc: array<vec4<f32>, TM * DV>;
    var m: array<f32, TM>;
    var l: array<f32, TM>;
    // Slots past the head are zero in Q, so clamped K and V reads there contribute nothing.
    // #unroll R TM
    {
        let base = (p.q_off + batch * p.q_batch + min(row0 + R, p.nq - 1u) * p.q_ld + head * p.d) / 4u;
        // #unroll V DV
        qs[R * DV + V] = select(vec4<f32>(0.0), p.scale * unit_f32(q[base + min(V * SG + lane, last)]), V * SG + lane < slots);
        // #end
        m[R] = NEG;
    }
    // #end
    for (var j0 = 0u; j0 < p.nk; j0 += SG) {
        // Scores of key j0 + lane against every query row; keys past the end are masked.
        let key = j0 + lane;
        let kbase = (p.k_off + batch * p.k_batch + min(key, p.nk - 1u) * p.k_ld + head * p.d) / 4u;
        var score: array<f32, TM>;
        // #unroll V DV
        // #unroll SRC SG
        {
            let kv = unit_f32(k[kbase + min(V * SG + SRC, last)]);
            // #unroll R TM
            score[R] += dot(subgroupBroadcast(qs[R * DV + V], SRC), kv);
            // #end
        }
        // #end
        // #end
        // #unroll R TM
        {
            // Past the end, or (causal) past the query row. Key 0 is never masked, so every
            // row's running maximum is real after the first chunk and masked keys weigh 0.
            let sc = select(NEG, score[R], (key < p.nk) & ((p.causal == 0u) | (key <= row0 + R)));
            let m_new = max(m[R], subgroupMax(sc));
            let correction = exp(m[R] - m_new);
            let pr = exp(sc - m_new);
            l[R] = l[R] * correction + subgroupAdd(pr);
            m[R] = m_new;
            score[R] = pr;
            // #unroll V DV
            acc[R * DV + V] *= correction;
            // #end
        }
        // #end
        // Each lane accumulates its own output slots over the chunk's keys (clamped past the end,
        // where the probability is zero).
        // #unroll SRC SG
        {
            let vbase = (p.v_off + batch * p.v_batch + min(j0 + SRC, p.nk - 1u) * p.v_ld + head * p.d) / 4u;
            // #unroll V DV
            {
                let vv = unit_f32(v[vbase + min(V * SG + lane, last)]);
                // #unroll R TM
                acc[R * DV + V] += subgroupBroadcast(score[R], SRC) * vv;
                // #end
            }
            // #end
        }
        // #end
    }
    // #unroll R TM
    // #unroll V DV
    {
        let row = row0 + R;
        let slot = V * SG + lane;
        if (row < p.nq) & (slot < slots) {
            o[(batch * p.o_batch + row * p.o_ld + head * p.d) / 4u + slot] = f32_unit(acc[R * DV + V] / l[R]);
        }
    }
    // #end
    // #end
}
