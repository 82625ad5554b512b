// What the matrix units reach through vkdiff's cooperative kernels with no device memory in the
// way, for `bench kernels`: each of a workgroup's 4 subgroups adds 2×2 products of FM×FK by
// FK×FN fragments REPS times into its sums, as gemm_coop.wgsl's inner loop does with its 2×2
// tile. SRC = 0 holds the operands in registers (the multiply-adds alone); SRC = 1 loads them
// from workgroup memory before every multiply-add, at the K offset ((r·step) mod KS)·FK of step r
// (step a push constant, so the compiler cannot hoist the loads), from tiles laid out as
// gemm_coop's: A [2·FM][LDA] and B stored N×K, [2·FN][LDA]. The two rates bound a GEMM's on these
// fragments, and the GEMM's own rate against them says what its memory traffic costs.
struct Params {
    reps: u32,
    step: u32,
}

var<immediate> p: Params;
// A (2·FM rows of KS·FK) then B (2·FN rows of KS·FK, N×K), row-major f16, copied as their bits
// into tiles of vec2<f32> (as gemm_coop.wgsl's).
@group(0) @binding(0) var<storage, read> operands: array<vec2<f32>>;
// Per workgroup, per subgroup, its 2×2 sums, each FM×FN row-major.
@group(0) @binding(1) var<storage, read_write> sums: array<vec4<f32>>;

const KS: u32 = 4u;
const WG: u32 = 4u * SG;
const LDA: u32 = KS * FK + 8u; // a tile row in f16, a multiple of 8 padded off a power of two
const ROW: u32 = KS * FK / 4u; // an operand row in vec4s
const TILE: u32 = 2u * FM * LDA / 4u; // A's tile in vec4s; B's follows it

var<workgroup> tiles: array<vec2<f32>, 2u * (FM + FN) * LDA / 4u>; // A, then B

@compute @workgroup_size(WG)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
    @builtin(subgroup_id) sid: u32,
) {
    // B's tile follows A's: operand row i / ROW is tile row i / ROW.
    for (var i = t; i < 2u * (FM + FN) * ROW; i += WG) {
        tiles[(i / ROW) * (LDA / 4u) + i % ROW] = operands[i];
    }
    workgroupBarrier();
    var fa: array<FA, 2>;
    var fb: array<FB, 2>;
    var acc: array<FC, 4>;
    // #unroll I 2
    {
        let at = I * FM * (LDA / 4u);
        fa[I] = coopLoadT<FA>(&tiles[at], LDA / 4u);
        let bt = TILE + I * FN * (LDA / 4u);
        fb[I] = coopLoad<FB>(&tiles[bt], LDA / 4u);
    }
    // #end
    for (var r = 0u; r < p.reps; r++) {
        if SRC == 1u {
            let kk = ((r * p.step) % KS) * FK / 4u;
            // #unroll I 2
            {
                let at = I * FM * (LDA / 4u) + kk;
                fa[I] = coopLoadT<FA>(&tiles[at], LDA / 4u);
                let bt = TILE + I * FN * (LDA / 4u) + kk;
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
        let at = ((wg.x * 4u + sid) * 4u + I) * FM * FN / 4u;
        coopStoreT(acc[I], &sums[at], FN / 4u);
    }
    // #end
}
