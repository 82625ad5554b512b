// Fused multi-head attention for any subgroup width: attention.wgsl's online softmax with the
// subgroup operations replaced by workgroup memory, so it runs wherever no subgroup variant
// fits the device (32- and 64-lane GPUs, other widths, heads wider than the subgroup variants
// hold). A workgroup of W invocations handles TM query rows of one head: the rows' scaled Q
// slots sit in workgroup memory, invocation t scores key j0 + t of each chunk of W keys against
// them, and owns output slots v·W + t (v < DV). Operands and parameters: attention_common.wgsl.
const SLOTS: u32 = DV * W;

var<workgroup> qs: array<vec4<f32>, TM * SLOTS>;
// The chunk's scores, [row][key].
var<workgroup> scores: array<f32, TM * W>;

@compute @workgroup_size(W)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let head = wg.y;
    let batch = wg.z;
    let row0 = wg.x * TM;
    let slots = p.d / 4u;
    for (var i = t; i < TM * slots; i += W) {
        let r = i / slots;
        let s = i % slots;
        let base = (p.q_off + batch * p.q_batch + min(row0 + r, p.nq - 1u) * p.q_ld + head * p.d) / 4u;
        qs[r * SLOTS + s] = p.scale * vec4<f32>(q[base + s]);
    }
    var acc: array<vec4<f32>, TM * DV>;
    var m: array<f32, TM>;
    var l: array<f32, TM>;
    // #unroll R TM
    m[R] = NEG;
    // #end
    workgroupBarrier();
    for (var j0 = 0u; j0 < p.nk; j0 += W) {
        let key = j0 + t;
        let kbase = (p.k_off + batch * p.k_batch + min(key, p.nk - 1u) * p.k_ld + head * p.d) / 4u;
        var score: array<f32, TM>;
        for (var s = 0u; s < slots; s++) {
            let kv = vec4<f32>(k[kbase + s]);
            // #unroll R TM
            score[R] += dot(qs[R * SLOTS + s], kv);
            // #end
        }
        // Masked past the end, or (causal) past the query row; key 0 never is.
        // #unroll R TM
        scores[R * W + t] = select(NEG, score[R], (key < p.nk) & ((p.causal == 0u) | (key <= row0 + R)));
        // #end
        workgroupBarrier();
        // #unroll R TM
        {
            var m_new = m[R];
            for (var j = 0u; j < W; j++) {
                m_new = max(m_new, scores[R * W + j]);
            }
            let correction = exp(m[R] - m_new);
            l[R] *= correction;
            m[R] = m_new;
            // #unroll V DV
            acc[R * DV + V] *= correction;
            // #end
        }
        // #end
        for (var j = 0u; j < min(W, p.nk - j0); j++) {
            let vbase = (p.v_off + batch * p.v_batch + (j0 + j) * p.v_ld + head * p.d) / 4u;
            var vv: array<vec4<f32>, DV>;
            // #unroll V DV
            vv[V] = vec4<f32>(v[vbase + min(V * W + t, slots - 1u)]);
            // #end
            // #unroll R TM
            {
                let pr = exp(scores[R * W + j] - m[R]);
                l[R] += pr;
                // #unroll V DV
                acc[R * DV + V] += pr * vv[V];
                // #end
            }
            // #end
        }
        // Every invocation has read the chunk's scores before the next chunk overwrites them.
        workgroupBarrier();
    }
    // #unroll R TM
    // #unroll V DV
    {
        let row = row0 + R;
        let slot = V * W + t;
        if (row < p.nq) & (slot < slots) {
            o[(batch * p.o_batch + row * p.o_ld + head * p.d) / 4u + slot] = vec4<S>(acc[R * DV + V] / l[R]);
        }
    }
    // #end
    // #end
}
