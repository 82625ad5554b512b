// A linear layer's product through VK_NV_cooperative_matrix2, for `bench kernels` and
// `VKDIFF_LINEAR=cm2` (a probe: it takes the product's place nowhere unasked until a GPU has
// timed it against gemm_coop.wgsl). Each workgroup holds one FM×FN accumulator of one batch
// entry and walks K in steps of FK, loading its FM×FK slice of A and FK×FN slice of B straight
// from device memory. WS = 1 gives the three matrices workgroup scope (compile.rs rewrites their
// scope): the WG invocations share them, and the driver stages the operands through shared
// memory as it sees fit, which is what the extension is for (ggml's coopmat2 GEMM works so).
// WS = 0 keeps subgroup scope, WG = SG: the same kernel on a driver that offers only the
// extension's flexible dimensions (Mesa 26.1's lavapipe), so that CI runs it. A [M][K] (row
// stride lda) and B stored N×K (row stride ldb, a linear layer's weight) are f16, read as the
// 32-bit words their pairs of halves make (compile.rs says why); cm2_store.wgsl finishes the tile
// into C (f16) as gemm_store4.wgsl would. M, N and K are multiples of FM, FN and FK, every stride
// of 8 values (the 16-byte rows matrix loads need): the runtime refuses other shapes. GE = 0
// (gemm_common.wgsl's parameters, the matrix products').
// As a_matrix_rows.wgsl's.
struct AParams {
    lda: u32,
    a_batch: u32,
}

@group(0) @binding(0) var<storage, read> a: array<f32>;
@group(0) @binding(1) var<storage, read> b: array<f32>;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>) {
    let row0 = wg.y * FM;
    let col0 = wg.x * FN;
    let batch = wg.z;
    var acc: FC;
    // Strides and offsets count words of two halves. Indices and strides through `let`s: naga 30
    // emits no expression that only a cooperative load's or store's arguments use.
    let lda = p.a.lda / 2u;
    let ldb = p.g.ldb / 2u;
    let a0 = (batch * p.a.a_batch + row0 * p.a.lda) / 2u;
    let b0 = (batch * p.g.b_batch + col0 * p.g.ldb) / 2u;
    for (var k0 = 0u; k0 < p.g.k; k0 += FK) {
        let at = a0 + k0 / 2u;
        let bt = b0 + k0 / 2u;
        let fa = coopLoadT<FA>(&a[at], lda);
        let fb = coopLoad<FB>(&b[bt], ldb);
        acc = coopMultiplyAdd(fa, fb, acc);
    }
    store_tile(acc, batch * p.g.c_batch + row0 * p.g.ldc + col0, col0);
}
