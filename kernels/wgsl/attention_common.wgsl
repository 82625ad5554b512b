// Attention's parameters, shared by every attention kernel: element (b, token, head, d) of an
// operand lies at off + b·batch + token·ld + head·D + d; D and every stride and offset % 4 = 0
// (vec4 reads). The operands are bound as attention_operands.wgsl declares them, or as the
// kernel does (attention_cm2.wgsl).
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
