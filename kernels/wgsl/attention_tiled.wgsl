// Fused multi-head attention for GPUs without matrix units, heads of up to 64 values (wider ones
// take attention_rows.wgsl): 16×16 invocations take TM = 64 query rows of one head and walk the
// keys in chunks of 64, both products as register-blocked tiles, like gemm_tiled_v4.wgsl.
// Invocation (tx, ty) holds the scores of rows 4·ty + i and keys 4·tx + j of a chunk, and the
// output of those rows at head values 4·tx + j, i, j < 4: each step of either product reads two
// vec4s of workgroup memory for 16 multiply-adds (attention_rows: one for four). Workgroup
// memory is two 16 KiB tiles, within the 32 KiB lavapipe and Apple GPUs offer: Q (scaled, staged
// again each chunk from the caches) and then P in one, K, the rows' maxima and then V in the
// other. A row's running maximum is shared once a chunk; each invocation keeps its own part of
// the row's sum until the end. Head values past D are zero in Q and K and never stored.
// Operands and parameters: attention_common.wgsl.
const DH: u32 = 64u;

var<workgroup> qp: array<vec4<f32>, DH * 16u>; // Q as [value][row / 4], then P as [row][key / 4]
var<workgroup> kv: array<vec4<f32>, DH * 16u>; // K as [value][key / 4], then V as [key][value / 4]

// A unit of four head values (quad dq) as f32, zero past the head.
fn unit(x: vec4<S>, dq: u32) -> vec4<f32> {
    return select(vec4<f32>(0.0), vec4<f32>(x), dq < p.d / 4u);
}

@compute @workgroup_size(16, 16)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let head = wg.y;
    let batch = wg.z;
    let row0 = wg.x * TM;
    let slots = p.d / 4u;
    let qhead = p.q_off + batch * p.q_batch + head * p.d;
    let khead = p.k_off + batch * p.k_batch + head * p.d;
    let vhead = p.v_off + batch * p.v_batch + head * p.d;
    var m = vec4<f32>(NEG);
    var l = vec4<f32>(0.0);
    var acc: array<vec4<f32>, 4>;
    for (var j0 = 0u; j0 < p.nk; j0 += 64u) {
        // Q and K transposed into [value][token]: units (token t % 64, quad t / 64 + 4·u), so a
        // subgroup's stores fall in distinct banks. Tokens past the end and quads past the head
        // read clamped ones: the quads are zeroed, the keys masked below, the rows never stored.
        // #unroll U 4
        {
            let r = t % 64u;
            let dq = t / 64u + 4u * U;
            let quad = min(dq, slots - 1u);
            let x = p.scale * unit(q[(qhead + min(row0 + r, p.nq - 1u) * p.q_ld) / 4u + quad], dq);
            let y = unit(k[(khead + min(j0 + r, p.nk - 1u) * p.k_ld) / 4u + quad], dq);
            // #unroll C 4
            qp[(4u * dq + C) * 16u + r / 4u][r % 4u] = x[C];
            kv[(4u * dq + C) * 16u + r / 4u][r % 4u] = y[C];
            // #end
        }
        // #end
        workgroupBarrier();
        // Scores s[i][j] of row 4·ty + i, key j0 + 4·tx + j.
        var s: array<vec4<f32>, 4>;
        for (var d = 0u; d < DH; d++) {
            let qv = qp[d * 16u + lid.y];
            let kq = kv[d * 16u + lid.x];
            // #unroll I 4
            s[I] += qv[I] * kq;
            // #end
        }
        var top = vec4<f32>(NEG);
        // #unroll I 4
        {
            let row = row0 + 4u * lid.y + I;
            let key = vec4<u32>(j0 + 4u * lid.x) + vec4<u32>(0u, 1u, 2u, 3u);
            let keep = key < vec4<u32>(p.nk) & (vec4<u32>(p.causal) == vec4<u32>(0u) | key <= vec4<u32>(row));
            s[I] = select(vec4<f32>(NEG), s[I], keep);
            top[I] = max(max(s[I].x, s[I].y), max(s[I].z, s[I].w));
        }
        // #end
        workgroupBarrier();
        // The rows' maxima over this chunk, from the 16 invocations that share them.
        kv[lid.x * 16u + lid.y] = top;
        workgroupBarrier();
        // #unroll X 16
        top = max(top, kv[X * 16u + lid.y]);
        // #end
        // The first chunk holds key 0, which no row masks, so `top` is finite from then on.
        let next = max(m, top);
        let correction = exp(m - next);
        l *= correction;
        m = next;
        // #unroll I 4
        {
            acc[I] *= correction[I];
            s[I] = exp(s[I] - vec4<f32>(m[I]));
            l[I] += s[I].x + s[I].y + s[I].z + s[I].w;
        }
        // #end
        workgroupBarrier();
        // P into [row][key]; V into [key][value] (units key t / 16 + 16·u, quad t % 16).
        // #unroll I 4
        qp[(4u * lid.y + I) * 16u + lid.x] = s[I];
        // #end
        // #unroll U 4
        {
            let key = t / 16u + 16u * U;
            let dq = t % 16u;
            kv[key * 16u + dq] = unit(v[(vhead + min(j0 + key, p.nk - 1u) * p.v_ld) / 4u + min(dq, slots - 1u)], dq);
        }
        // #end
        workgroupBarrier();
        for (var kq = 0u; kq < 16u; kq++) {
            var pv: array<vec4<f32>, 4>;
            // #unroll I 4
            pv[I] = qp[(4u * lid.y + I) * 16u + kq];
            // #end
            // #unroll J 4
            {
                let vv = kv[(4u * kq + J) * 16u + lid.x];
                // #unroll I 4
                acc[I] += pv[I][J] * vv;
                // #end
            }
            // #end
        }
        workgroupBarrier();
    }
    // Each row's sum, from the 16 invocations that share it.
    kv[lid.x * 16u + lid.y] = l;
    workgroupBarrier();
    var sum = vec4<f32>(0.0);
    // #unroll X 16
    sum += kv[X * 16u + lid.y];
    // #end
    // #unroll I 4
    {
        let row = row0 + 4u * lid.y + I;
        if (row < p.nq) & (lid.x < slots) {
            o[(batch * p.o_batch + row * p.o_ld + head * p.d) / 4u + lid.x] = vec4<S>(acc[I] / sum[I]);
        }
    }
    // #end
}
