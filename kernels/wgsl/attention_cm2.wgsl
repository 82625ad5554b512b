// Attention through VK_NV_cooperative_matrix2, for `bench kernels`, its kernel test and
// `VKDIFF_ATTENTION=cm2` (a probe, as gemm_cm2.wgsl is: no network takes it unasked until a GPU
// has timed it against attention_coop.wgsl). The softmax stays in the matrix registers, as ggml's flash_attn_cm2
// keeps it: the extension's row reductions give each row's maximum and sum, its per-element
// operations the powers, the mask and the rescaling, and its conversion turns the weights into
// P·V's operand; nothing passes through workgroup memory between the two products, where
// attention_coop.wgsl writes the scores out, runs the softmax on lanes and reads P back.
//
// A workgroup takes FM query rows of one head against chunks of FN keys, heads of up to FK
// values (every matrix spans the whole tile: S = Q·Kᵀ is the FM×FN×FK product, declared 8×8
// here, and O += P·V the FM×FK×FN one, declared 16×16; compile.rs gives them their shapes, PV = 1,
// so FN ≠ FK). WS = 1 gives the matrices workgroup scope, shared by WG invocations (NVIDIA's
// drivers); WS = 0 subgroup scope on a workgroup of one subgroup (Mesa 26.1's lavapipe, for CI).
// Q is staged in workgroup memory as attention_coop.wgsl stages it (attention_staging.wgsl). K and
// V load in place, the driver staging them as it sees fit (what workgroup scope is for), where
// the heads are FK values wide, every offset and stride a multiple of 8 values (rows of 16
// bytes, as matrix loads need) and the chunk is whole; other chunks (the last, past the keys'
// end) are staged too, keys past the end clamped and then masked. The online softmax is
// in base 2 with the reference moving every chunk: M = max(M, rowmax(S)), P = 2^(S − M) rounded
// to f16 as P·V takes it (and summed so), O and the row sums L scaled by 2^(M_old − M). Row
// statistics (M, L) are held as FM×FN accumulators whose rows repeat one value, and smeared to
// FM×FK to scale O.
const DH: u32 = FK;
const KC: u32 = FN;
const ROWS: u32 = FM; // ≤ 2·KC: Q is staged where K and V go
const SLOTS: u32 = DH / 4u;
const_assert PU == KC * SLOTS / WG;
const_assert ROWS <= 2u * KC;
const LOG2E: f32 = 1.4426950408889634;
const LD: u32 = DH + 8u; // Q, K and V rows (f16; a multiple of 8 values, 16 bytes)
const LO: u32 = DH + 4u; // output rows (f32)

// The operands as words of f16 pairs seen as f32 (naga types a matrix load by the pointer it
// reads through); the staging reads them as their bits.
@group(0) @binding(0) var<storage, read> q: array<Words>;
@group(0) @binding(1) var<storage, read> k: array<Words>;
@group(0) @binding(2) var<storage, read> v: array<Words>;
@group(0) @binding(3) var<storage, read_write> o: array<Words>;

var<workgroup> kv: array<Words, 2u * KC * LD / 4u>; // Q's rows, then a staged chunk's K rows and V rows
var<workgroup> chunk_in_place: u32; // whether this chunk's K and V load in place
var<workgroup> out_rows: array<Words, ROWS * LO / 2u>;

alias FP = coop_mat16x16<f32, A>; // P: FM×FN, f16
alias FV = coop_mat16x16<f32, B>; // V: FN×FK, f16
alias FO = coop_mat16x16<f32, C>; // O: FM×FK, f32

// The functions the extension's operations apply (spirv_rewrite.rs): reductions combine two
// elements; per-element operations take (row, column, element, operands…).
fn larger(a: f32, b: f32) -> f32 {
    return max(a, b);
}

fn plus(a: f32, b: f32) -> f32 {
    return a + b;
}

fn lowest(row: u32, col: u32, x: f32) -> f32 {
    return NEG;
}

fn power(row: u32, col: u32, x: f32) -> f32 {
    return exp2(x);
}

// A weight as P·V takes it: rounded to f16.
fn weight(row: u32, col: u32, x: f32) -> f32 {
    return f32(f16(exp2(x)));
}

fn larger_each(row: u32, col: u32, x: f32, y: f32) -> f32 {
    return max(x, y);
}

fn scaled_sum(row: u32, col: u32, l: f32, scale: f32, sum: f32) -> f32 {
    return l * scale + sum;
}

fn times(row: u32, col: u32, x: f32, y: f32) -> f32 {
    return x * y;
}

fn over(row: u32, col: u32, x: f32, y: f32) -> f32 {
    return x / y;
}

// A score, or NEG for a key past the end or, under a causal mask, after the query.
fn unmasked(row: u32, col: u32, x: f32, j0: u32, row0: u32) -> f32 {
    let key = j0 + col;
    let live = (key < p.nk) & ((p.causal == 0u) | (key <= row0 + row));
    return select(NEG, x, live);
}

// Placeholders of the extension's operations (spirv_rewrite.rs replaces their calls; their
// bodies only give naga a result of the right type).
fn nv_reduce_rows(m: FC, combine: f32) -> FC {
    return m;
}

fn nv_reduce_rows_to_out(m: FC, combine: f32) -> FO {
    var smeared: FO;
    return smeared;
}

fn nv_each(m: FC, f: f32) -> FC {
    return m;
}

fn nv_each_with(m: FC, f: f32, y: FC) -> FC {
    return m;
}

fn nv_each_with_two(m: FC, f: f32, y: FC, z: FC) -> FC {
    return m;
}

fn nv_each_out(m: FO, f: f32, y: FO) -> FO {
    return m;
}

fn nv_each_masked(m: FC, f: f32, j0: u32, row0: u32) -> FC {
    return m;
}

fn nv_convert(m: FC) -> FP {
    var converted: FP;
    return converted;
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let head = wg.y;
    let batch = wg.z;
    let row0 = wg.x * ROWS;
    var rk: array<Unit, PU>;
    var rv: array<Unit, PU>;
    stage_q(row0, head, batch, t);
    workgroupBarrier();
    let qt = 0u; // indices and strides through `let`s (gemm_cm2.wgsl says why)
    let qs = LD / 4u;
    let qf = coopLoadT<FA>(&kv[qt], qs);
    var zero: FC;
    var top = nv_each(zero, lowest(0u, 0u, 0.0)); // M
    var sums: FC; // L
    var acc: FO; // O
    let kt = 0u;
    let vt = KC * LD / 4u;
    let aligned = ((p.k_off | p.k_batch | p.k_ld | p.v_off | p.v_batch | p.v_ld) % 8u) == 0u;
    let in_place = (p.d == DH) & aligned;
    let ks = p.k_ld / 4u;
    let vs = p.v_ld / 4u;
    for (var j0 = 0u; j0 < p.nk; j0 += KC) {
        // K rows [key][d] read column-major are Kᵀ; V rows are read row-major.
        var kf: FB;
        var vf: FV;
        // The same for every invocation, but naga proves a matrix load's control flow uniform only
        // through workgroup memory (its analysis takes the loop counter for divergent).
        if t == 0u {
            chunk_in_place = u32(in_place & (j0 + KC <= p.nk));
        }
        if workgroupUniformLoad(&chunk_in_place) != 0u {
            let ka = (p.k_off + batch * p.k_batch + j0 * p.k_ld + head * DH) / 4u;
            let va = (p.v_off + batch * p.v_batch + j0 * p.v_ld + head * DH) / 4u;
            kf = coopLoad<FB>(&k[ka], ks);
            vf = coopLoadT<FV>(&v[va], vs);
        } else {
            // Every matrix is done with what `kv` held (Q, or the chunk staged before) first.
            workgroupBarrier();
            fetch_kv(&rk, &rv, j0, t, head, batch);
            store_kv(&rk, &rv, t);
            workgroupBarrier();
            kf = coopLoad<FB>(&kv[kt], qs);
            vf = coopLoadT<FV>(&kv[vt], qs);
        }
        // S = Q·Kᵀ in base 2.
        var s = coopMultiplyAdd(qf, kf, zero) * LOG2E;
        if (j0 + KC > p.nk) | (p.causal != 0u) {
            s = nv_each_masked(s, unmasked(0u, 0u, 0.0, 0u, 0u), j0, row0);
        }
        let now = nv_each_with(nv_reduce_rows(s, larger(0.0, 0.0)), larger_each(0u, 0u, 0.0, 0.0), top);
        let weights = nv_each(s - now, weight(0u, 0u, 0.0));
        // 2^(NEG − M) = 0 on the first chunk, whose O and L are still zero.
        let scale = nv_each(top - now, power(0u, 0u, 0.0));
        top = now;
        let chunk_sums = nv_reduce_rows(weights, plus(0.0, 0.0));
        sums = nv_each_with_two(sums, scaled_sum(0u, 0u, 0.0, 0.0, 0.0), scale, chunk_sums);
        acc = nv_each_out(acc, times(0u, 0u, 0.0, 0.0), nv_reduce_rows_to_out(scale, larger(0.0, 0.0)));
        acc = coopMultiplyAdd(nv_convert(weights), vf, acc);
    }
    acc = nv_each_out(acc, over(0u, 0u, 0.0, 0.0), nv_reduce_rows_to_out(sums, larger(0.0, 0.0)));
    let ot = 0u;
    let os = LO / 2u;
    coopStoreT(acc, &out_rows[ot], os);
    workgroupBarrier();
    let slots = p.d / 4u;
    for (var i = t; i < ROWS * SLOTS; i += WG) {
        let r = i / SLOTS;
        let s = i % SLOTS;
        let query = row0 + r;
        if (query < p.nq) & (s < slots) {
            let at = r * os + 2u * s;
            let x = vec4<f32>(out_rows[at], out_rows[at + 1u]);
            o[(batch * p.o_batch + query * p.o_ld + head * p.d) / 4u + s] = bitcast<Words>(narrow(x));
        }
    }
}
