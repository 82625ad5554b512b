// Attention's operands and parameters, shared by the subgroup (attention.wgsl) and workgroup
// (attention_wg.wgsl) kernels. Element (b, token, head, d) of an operand lies at
// off + b·batch + token·ld + head·D + d; D and every stride and offset % 4 = 0 (vec4 reads).
@group(0) @binding(0) var<storage, read> q: array<Unit>;
@group(0) @binding(1) var<storage, read> k: array<Unit>;
@group(0) @binding(2) var<storage, read> v: array<Unit>;
@group(0) @binding(3) var<storage, read_write> o: array<Unit>;

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
    q_off: u32,
    k_off: u32,
    v_off: u32,
    causal: u32,
}

var<immediate> p: Params;

const NEG: f32 = -1.0e30;
