// GEMM core for GPUs without matrix units, and for f32 products on any GPU, on vec4-aligned
// operands (the runtime sends other shapes to gemm_tiled.wgsl). 16×16 invocations share a
// BM×128 tile (BM = 64·RH) staged through workgroup memory in K-steps of 16; invocation (tx, ty)
// owns rows 4·ty + 64·h + i (h < RH) and columns 4·tx + 64·j + c (j < 2), i, c < 4: RH·32
// outputs as vec4 sums. Each step of the inner loop reads RH + 2 vec4s of workgroup memory for
// RH·32 multiply-adds (gemm_tiled.wgsl: 8 values for 16). Both tiles are stored K-major, A
// transposed on its way in, so those reads are whole vec4s: two distinct addresses of A a
// subgroup (broadcasts), 16 consecutive vec4s of B. Tile rows of BM + 4 and 132 values keep the
// transposed stores to two-way bank conflicts at most. Each invocation stages RH units of four
// along K of A and two of B (along K, or along N when B is K×N), so a warp reads 8 rows of 16
// consecutive values; the next step's units are loaded into registers while this step's
// multiply-adds run. Rows past M are clamped (never stored), units past N and K are zero.
const BM: u32 = 64u * RH;
const BN: u32 = 128u;
const BK: u32 = 16u;
const GB: u32 = 4u; // GEGLU blocks (gemm_common.wgsl): unused, GPUs apply GEGLU after the product
const LA: u32 = BM / 4u + 1u; // tile rows in vec4s: A [BK][LA], B [BK][LB]
const LB: u32 = BN / 4u + 1u;

var<workgroup> a_tile: array<vec4<f32>, BK * LA>;
var<workgroup> b_tile: array<vec4<f32>, BK * LB>;

// This invocation's units of the K-step at k0, as stored, and whether each is inside the
// product: A rows t/4 + 64·i and B rows (BT = 1) t/4 + 64·i at K offset 4·(t % 4); B stored K×N:
// rows t/32 + 8·i at columns 4·(t % 32). The reads are in bounds (clamped); the masks and the
// widening to f32 wait for the stores at the next step, so that nothing waits for a load before
// this step's multiply-adds (gemm_coop.wgsl).
fn fetch(
    rows: ptr<function, array<RowCtx, RH>>,
    ra: ptr<function, array<Unit, RH>>,
    rb: ptr<function, array<Unit, 2>>,
    ia: ptr<function, array<bool, RH>>,
    ib: ptr<function, array<bool, 2>>,
    k0: u32,
    t: u32,
    col0: u32,
    boff: u32,
) {
    let ka = k0 + 4u * (t % 4u);
    let kc = k_ctx(ka);
    // #unroll I RH
    (*ra)[I] = a_unit((*rows)[I], kc);
    (*ia)[I] = (ka < p.g.k) & a_unit_inside((*rows)[I], kc);
    // #end
    // #unroll I 2
    {
        var k = ka;
        var n = col0 + t / 4u + 64u * I;
        if BT == 0u {
            k = k0 + t / 32u + 8u * I;
            n = col0 + 4u * (t % 32u);
        }
        (*rb)[I] = b_unit(boff, k, n);
        (*ib)[I] = b_unit_inside(k, n);
    }
    // #end
}

// A unit as the tiles hold it: widened to f32, zero outside the product.
fn staged(unit: Unit, inside: bool) -> vec4<f32> {
    return select(vec4<f32>(0.0), vec4<f32>(unit), inside);
}

@compute @workgroup_size(16, 16)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let row0 = wg.y * BM;
    let col0 = wg.x * BN;
    let batch = wg.z;
    let boff = batch * p.g.b_batch;
    // Where this invocation's staged units go: K row 4·(t % 4) + c, vec4 column t/16 + 16·i,
    // lane (t/4) % 4 (A and B stored N×K, transposed); B stored K×N: row t/32 + 8·i, column t % 32.
    let kq = 4u * (t % 4u);
    let slot = t / 16u;
    let lane = (t / 4u) % 4u;
    var rows: array<RowCtx, RH>;
    // #unroll I RH
    rows[I] = row_ctx(batch, row0 + t / 4u + 64u * I);
    // #end
    var ra: array<Unit, RH>;
    var rb: array<Unit, 2>;
    var ia: array<bool, RH>;
    var ib: array<bool, 2>;
    fetch(&rows, &ra, &rb, &ia, &ib, 0u, t, col0, boff);
    var acc: array<vec4<f32>, 8u * RH>;
    for (var k0 = 0u; k0 < p.g.k; k0 += BK) {
        // #unroll I RH
        {
            let unit = staged(ra[I], ia[I]);
            // #unroll C 4
            a_tile[(kq + C) * LA + slot + 16u * I][lane] = unit[C];
            // #end
        }
        // #end
        // #unroll I 2
        {
            let unit = staged(rb[I], ib[I]);
            if BT == 1u {
                // #unroll C 4
                b_tile[(kq + C) * LB + slot + 16u * I][lane] = unit[C];
                // #end
            } else {
                b_tile[(t / 32u + 8u * I) * LB + t % 32u] = unit;
            }
        }
        // #end
        workgroupBarrier();
        fetch(&rows, &ra, &rb, &ia, &ib, k0 + BK, t, col0, boff);
        for (var kk = 0u; kk < BK; kk++) {
            let b0 = b_tile[kk * LB + lid.x];
            let b1 = b_tile[kk * LB + 16u + lid.x];
            // #unroll H RH
            {
                let av = a_tile[kk * LA + 16u * H + lid.y];
                // #unroll I 4
                acc[8u * H + 2u * I] += av[I] * b0;
                acc[8u * H + 2u * I + 1u] += av[I] * b1;
                // #end
            }
            // #end
        }
        workgroupBarrier();
    }
    // #unroll H RH
    // #unroll I 4
    // #unroll J 2
    store4(batch, row0 + 64u * H + 4u * lid.y + I, col0 + 64u * J + 4u * lid.x, acc[8u * H + 2u * I + J]);
    // #end
    // #end
    // #end
}
