// GEMM core for GPUs and for shapes the vec4 variant cannot take: 64×64 output tiles staged
// through workgroup memory in K-steps of 16, 16×16 invocations each computing 4×4 outputs.
// Any M, N, K and strides. B is K×N (BT = 0) or N×K (BT = 1).
@group(0) @binding(1) var<storage, read> b: array<S>;
@group(0) @binding(2) var<storage, read> bias: array<S>;
@group(0) @binding(3) var<storage, read_write> c: array<S>;

const TILE: u32 = 64u;
const BK: u32 = 16u;

var<workgroup> a_tile: array<f32, 1024>; // [BK][TILE]
var<workgroup> b_tile: array<f32, 1024>; // [BK][TILE]

fn load_b1(boff: u32, k: u32, n: u32) -> f32 {
    if k >= p.g.k || n >= p.g.n {
        return 0.0;
    }
    if BT == 0u {
        return f32(b[boff + k * p.g.ldb + n]);
    }
    return f32(b[boff + n * p.g.ldb + k]);
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
    let tk = t % BK;
    // This invocation stages rows t/16 + 16·i of the A tile.
    var rows: array<RowCtx, 4>;
    for (var i = 0u; i < 4u; i++) {
        rows[i] = row_ctx(batch, row0 + t / BK + 16u * i);
    }
    var acc: array<f32, 16>;
    for (var k0 = 0u; k0 < p.g.k; k0 += BK) {
        let ka = k0 + tk;
        let kc = k_ctx(ka);
        for (var i = 0u; i < 4u; i++) {
            a_tile[tk * TILE + t / BK + 16u * i] = select(0.0, load_a1(rows[i], kc), ka < p.g.k);
            let e = t + 256u * i;
            b_tile[e] = load_b1(boff, k0 + e / TILE, col0 + e % TILE);
        }
        workgroupBarrier();
        for (var kk = 0u; kk < BK; kk++) {
            var av: array<f32, 4>;
            var bv: array<f32, 4>;
            for (var i = 0u; i < 4u; i++) {
                av[i] = a_tile[kk * TILE + lid.y * 4u + i];
                bv[i] = b_tile[kk * TILE + lid.x * 4u + i];
            }
            for (var i = 0u; i < 4u; i++) {
                for (var j = 0u; j < 4u; j++) {
                    acc[4u * i + j] += av[i] * bv[j];
                }
            }
        }
        workgroupBarrier();
    }
    for (var i = 0u; i < 4u; i++) {
        let row = row0 + lid.y * 4u + i;
        for (var j = 0u; j < 4u; j++) {
            let col = col0 + lid.x * 4u + j;
            if row < p.g.m && col < p.g.n {
                let at = batch * p.g.c_batch + row * p.g.ldc + col;
                var v = p.g.alpha * acc[4u * i + j];
                if (p.g.flags & FLAG_BIAS) != 0u {
                    v += f32(bias[col]);
                }
                if (p.g.flags & FLAG_ACCUMULATE) != 0u {
                    v += f32(c[at]);
                }
                if (p.g.flags & FLAG_RELU) != 0u {
                    v = max(v, 0.0);
                }
                c[at] = S(v);
            }
        }
    }
}
