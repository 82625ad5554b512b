// What the matrix units reach through vkdiff's cooperative kernels with no device memory in the
// way, for `bench kernels`: each of a workgroup's 4 subgroups adds 2×2 products of CM×CM
// fragments REPS times into its sums, as gemm_coop.wgsl's inner loop does with its 2×2 tile.
// SRC = 0 holds the operands in registers (the multiply-adds alone); SRC = 1 loads them from
// workgroup memory before every multiply-add, at the K offset ((r·step) mod KS)·CM of step r
// (step a push constant, so the compiler cannot hoist the loads), from tiles laid out as
// gemm_coop's: A [2·CM][LDA] and B stored N×K alike. The two rates bound a GEMM's on these
// fragments, and the GEMM's own rate against them says what its memory traffic costs.
struct Params {
    reps: u32,
    step: u32,
}

var<immediate> p: Params;
// A (2·CM rows of KS·CM) then B (the same, N×K), row-major f16.
@group(0) @binding(0) var<storage, read> operands: array<vec4<f16>>;
// Per workgroup, per subgroup, its 2×2 sums, each CM×CM row-major.
@group(0) @binding(1) var<storage, read_write> sums: array<vec4<f32>>;

const KS: u32 = 4u;
const WG: u32 = 4u * SG;
const LDA: u32 = KS * CM + 8u; // a tile row in f16, a multiple of 8 padded off a power of two
const ROW: u32 = KS * CM / 4u; // an operand row in vec4s
const TILE: u32 = 2u * CM * LDA / 4u; // one tile in vec4s

var<workgroup> tiles: array<vec4<f16>, 2u * TILE>; // A, then B

@compute @workgroup_size(WG)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(subgroup_id) sid: u32,
) {
    // B's tile follows A's: operand row i / ROW is tile row i / ROW.
    for (var i = t; i < 4u * CM * ROW; i += WG) {
        tiles[(i / ROW) * (LDA / 4u) + i % ROW] = operands[i];
    }
    workgroupBarrier();
    var fa: array<FA, 2>;
    var fb: array<FB, 2>;
    var acc: array<FC, 4>;
    // #unroll I 2
    {
        let at = I * CM * (LDA / 4u);
        fa[I] = coopLoadT<FA>(&tiles[at], LDA / 4u);
        let bt = TILE + I * CM * (LDA / 4u);
        fb[I] = coopLoad<FB>(&tiles[bt], LDA / 4u);
    }
    // #end
    for (var r = 0u; r < p.reps; r++) {
        if SRC == 1u {
            let kk = ((r * p.step) % KS) * CM / 4u;
            // #unroll I 2
            {
                let at = I * CM * (LDA / 4u) + kk;
                fa[I] = coopLoadT<FA>(&tiles[at], LDA / 4u);
                let bt = TILE + I * CM * (LDA / 4u) + kk;
                fb[I] = coopLoad<FB>(&tiles[bt], LDA / 4u);
            }
            // #end
        }
        // #unroll I 2
        // #unroll J 2
        acc[2 * I + J] = coopMultiplyAdd(fa[I], fb[J], acc[2 * I + J]);
        // #end
        // #end
    }
    // #unroll I 4
    {
        let at = ((wg.x * 4u + sid) * 4u + I) * CM * CM / 4u;
        coopStoreT(acc[I], &sums[at], CM / 4u);
    }
    // #end
}
