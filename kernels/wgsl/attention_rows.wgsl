// Fused multi-head attention for GPUs, heads of up to 4·DS values: a workgroup of 64
// invocations takes 64 query rows of one head, one row per invocation, with the row's scaled Q
// and its output in registers. Keys and values pass through workgroup memory in chunks of KC,
// which every invocation reads at the same address (a broadcast); each row keeps its own online
// softmax over blocks of 8 keys, so no invocation computes work another discards and none waits
// for another between chunks. Heads wider than 4·DS take attention_wg.wgsl. Register arrays are
// indexed only by unrolled constants (GPU compilers spill dynamically indexed ones). Operands
// and parameters: attention_common.wgsl.
const ROWS: u32 = 64u;

var<workgroup> ks: array<vec4<f32>, KC * DS>;
var<workgroup> vs: array<vec4<f32>, KC * DS>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let head = wg.y;
    let batch = wg.z;
    let row = wg.x * ROWS + t;
    let slots = p.d / 4u;
    let qbase = (p.q_off + batch * p.q_batch + min(row, p.nq - 1u) * p.q_ld + head * p.d) / 4u;
    var qv: array<vec4<f32>, DS>;
    var acc: array<vec4<f32>, DS>;
    // #unroll SL DS
    qv[SL] = select(vec4<f32>(0.0), p.scale * vec4<f32>(q[qbase + min(SL, slots - 1u)]), SL < slots);
    // #end
    var m = NEG;
    var l = 0.0;
    for (var j0 = 0u; j0 < p.nk; j0 += KC) {
        // Consecutive invocations copy consecutive slots of a key row; keys past the end are
        // clamped here and masked below. Slots past the head are never written and stay zero
        // (workgroup memory starts zeroed: the runtime requires it), matching Q's zero slots.
        for (var i = t; i < KC * slots; i += ROWS) {
            let key = min(j0 + i / slots, p.nk - 1u);
            let s = i % slots;
            let kb = (p.k_off + batch * p.k_batch + key * p.k_ld + head * p.d) / 4u;
            let vb = (p.v_off + batch * p.v_batch + key * p.v_ld + head * p.d) / 4u;
            ks[(i / slots) * DS + s] = vec4<f32>(k[kb + s]);
            vs[(i / slots) * DS + s] = vec4<f32>(v[vb + s]);
        }
        workgroupBarrier();
        for (var j = 0u; j < KC; j += 8u) {
            // Key j0 + j + J against this row; masked past the end or (causal) past the row.
            // The first block holds key 0, which never is, so `top` is finite from then on.
            var score: array<f32, 8>;
            var top = m;
            // #unroll J 8
            {
                var s = 0.0;
                // #unroll SL DS
                s += dot(qv[SL], ks[(j + J) * DS + SL]);
                // #end
                let key = j0 + j + J;
                score[J] = select(NEG, s, (key < p.nk) & ((p.causal == 0u) | (key <= row)));
                top = max(top, score[J]);
            }
            // #end
            let correction = exp(m - top);
            l *= correction;
            // #unroll SL DS
            acc[SL] *= correction;
            // #end
            // #unroll J 8
            {
                let weight = exp(score[J] - top);
                l += weight;
                // #unroll SL DS
                acc[SL] += weight * vs[(j + J) * DS + SL];
                // #end
            }
            // #end
            m = top;
        }
        // Every invocation has read the chunk before the next one overwrites it.
        workgroupBarrier();
    }
    let obase = (batch * p.o_batch + row * p.o_ld + head * p.d) / 4u;
    // #unroll SL DS
    if (row < p.nq) & (SL < slots) {
        o[obase + SL] = vec4<S>(acc[SL] / l);
    }
    // #end
}
