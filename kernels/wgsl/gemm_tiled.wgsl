// GEMM core for GPUs and for shapes the vec4 variant cannot take: 64×64 output tiles staged
// through workgroup memory in K-steps of 16, 16×16 invocations each computing 4×4 outputs
// spaced 16 apart (rows lid.y + 16·i, columns lid.x + 16·j), so tile reads and C stores are
// consecutive across a subgroup. Any M, N, K and strides. B is K×N (BT = 0) or N×K (BT = 1).
// An operand whose rows run along K (A, and B when BT = 1) is read k-fastest, 16 consecutive
// values of a row per 16 invocations, and stored transposed into a tile padded to 65 columns,
// which keeps those stores nearly free of bank conflicts. Register arrays are indexed only by
// unrolled constants: GPU compilers spill dynamically indexed ones to memory.
@group(0) @binding(1) var<storage, read> b: array<S>;

const TILE: u32 = 64u;
const BK: u32 = 16u;
const LD: u32 = 65u; // row length of the [BK][LD] tiles
// GEGLU blocks (gemm_common.wgsl): columns lid.x + 16·j pair j = 0 with 1 and 2 with 3.
const GB: u32 = 16u;

var<workgroup> a_tile: array<f32, 1040>;
var<workgroup> b_tile: array<f32, 1040>;

// B at (k, n), zero past K and N: read clamped and masked, with no branch around the load.
fn load_b1(boff: u32, k: u32, n: u32) -> f32 {
    let kc = min(k, p.g.k - 1u);
    let nc = min(n, p.g.n - 1u);
    var value: S;
    if BT == 0u {
        value = b[boff + kc * p.g.ldb + nc];
    } else {
        value = b[boff + b_row(nc) * p.g.ldb + kc];
    }
    return select(0.0, f32(value), (k < p.g.k) & (n < p.g.n));
}

@compute @workgroup_size(16, 16)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let row0 = wg.y * TILE;
    let col0 = wg.x * TILE;
    let batch = wg.z;
    let boff = batch * p.g.b_batch;
    // This invocation stages k = k0 + tk of tile rows (A) and columns (B, BT = 1) tr + 16·i.
    let tk = t % BK;
    let tr = t / BK;
    var rows: array<RowCtx, 4>;
    // #unroll I 4
    rows[I] = row_ctx(batch, row0 + tr + 16u * I);
    // #end
    var acc: array<f32, 16>;
    for (var k0 = 0u; k0 < p.g.k; k0 += BK) {
        let ka = k0 + tk;
        let kc = k_ctx(ka);
        // #unroll I 4
        a_tile[tk * LD + tr + 16u * I] = select(0.0, load_a1(rows[I], kc), ka < p.g.k);
        if BT == 1u {
            b_tile[tk * LD + tr + 16u * I] = load_b1(boff, ka, col0 + tr + 16u * I);
        } else {
            b_tile[(t / TILE + 4u * I) * LD + t % TILE] = load_b1(boff, k0 + t / TILE + 4u * I, col0 + t % TILE);
        }
        // #end
        workgroupBarrier();
        for (var kk = 0u; kk < BK; kk++) {
            var av: array<f32, 4>;
            var bv: array<f32, 4>;
            // #unroll I 4
            av[I] = a_tile[kk * LD + lid.y + 16u * I];
            bv[I] = b_tile[kk * LD + lid.x + 16u * I];
            // #end
            // #unroll I 4
            // #unroll J 4
            acc[4u * I + J] += av[I] * bv[J];
            // #end
            // #end
        }
        workgroupBarrier();
    }
    if GE == 1u {
        // #unroll I 4
        // #unroll H 2
        {
            let at = 4u * I + 2u * H;
            store_geglu(batch, row0 + lid.y + 16u * I, col0 + lid.x + 32u * H, acc[at], acc[at + 1u]);
        }
        // #end
        // #end
    } else {
        // #unroll I 4
        // #unroll J 4
        store(batch, row0 + lid.y + 16u * I, col0 + lid.x + 16u * J, acc[4u * I + J]);
        // #end
        // #end
    }
}
