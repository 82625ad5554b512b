// How the matrix-unit attention kernels (attention_coop.wgsl, attention_cm2.wgsl) stage their
// operands in workgroup memory: Q's ROWS rows, then each chunk of KC keys' K and V rows, all f16
// rows of LD values in `kv` (K's first, then V's), fetched into registers first (attention_coop
// fetches each chunk while the one before is computed, so that the loads' latency hides). Each
// kernel declares `kv`, ROWS, KC, SLOTS
// (DH/4, a head's units), LD and WG; PU (a parameter: the `#unroll` count) is KC·SLOTS/WG, the
// units of a chunk's K (and V) per invocation. The operands are read as their bits, in whichever
// type of unit the kernel binds them (attention_operands.wgsl's, or attention_cm2.wgsl's).

// A unit of the operands widened to f32, and four values rounded to f16 as a unit.
fn widen(u: Unit) -> vec4<f32> {
    return vec4<f32>(unpack2x16float(u.x), unpack2x16float(u.y));
}

fn narrow(x: vec4<f32>) -> Unit {
    return Unit(pack2x16float(x.xy), pack2x16float(x.zw));
}

// A unit as the tiles hold it (gemm_coop.wgsl): its bits.
fn tiled(u: Unit) -> Words {
    return bitcast<Words>(u);
}

// Q's rows row0.. of `head`, scaled, into `kv`: rows past the end clamped, slots past the head
// zero (so that they meet K's clamped slots as zeros).
fn stage_q(row0: u32, head: u32, batch: u32, t: u32) {
    let slots = p.d / 4u;
    for (var i = t; i < ROWS * SLOTS; i += WG) {
        let r = i / SLOTS;
        let s = i % SLOTS;
        let token = min(row0 + r, p.nq - 1u);
        let at = (p.q_off + batch * p.q_batch + token * p.q_ld + head * p.d) / 4u + min(s, slots - 1u);
        kv[r * (LD / 4u) + s] = tiled(select(Unit(), narrow(p.scale * widen(bitcast<Unit>(q[at]))), s < slots));
    }
}

// Units t + WG·u of the chunk at key j0 (K and V rows [KC][SLOTS]) into registers, staged as
// loaded: keys past the end clamped (their scores are masked, so their weights are zero), slots
// past the head clamped too (in K they meet Q's zeros; in V they make output columns that are
// never stored).
fn fetch_kv(
    rk: ptr<function, array<Unit, PU>>,
    rv: ptr<function, array<Unit, PU>>,
    j0: u32,
    t: u32,
    head: u32,
    batch: u32,
) {
    let slots = p.d / 4u;
    // #unroll U PU
    {
        let i = t + WG * U;
        let s = i % SLOTS;
        let key = min(j0 + i / SLOTS, p.nk - 1u);
        let sl = min(s, slots - 1u);
        let ka = (p.k_off + batch * p.k_batch + key * p.k_ld + head * p.d) / 4u + sl;
        let va = (p.v_off + batch * p.v_batch + key * p.v_ld + head * p.d) / 4u + sl;
        (*rk)[U] = bitcast<Unit>(k[ka]);
        (*rv)[U] = bitcast<Unit>(v[va]);
    }
    // #end
}

// The fetched chunk into `kv`.
fn store_kv(rk: ptr<function, array<Unit, PU>>, rv: ptr<function, array<Unit, PU>>, t: u32) {
    // #unroll U PU
    {
        let i = t + WG * U;
        kv[(i / SLOTS) * (LD / 4u) + i % SLOTS] = tiled((*rk)[U]);
        kv[(KC + i / SLOTS) * (LD / 4u) + i % SLOTS] = tiled((*rv)[U]);
    }
    // #end
}
