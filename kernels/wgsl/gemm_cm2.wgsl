// A linear layer's product through VK_NV_cooperative_matrix2, for `bench kernels` only (a probe:
// it takes the product's place nowhere until a GPU has timed it against gemm_coop.wgsl). Each
// workgroup holds one FM×FN accumulator and walks K in steps of FK, loading its FM×FK slice of A
// and FK×FN slice of B straight from device memory. WS = 1 gives the three matrices workgroup
// scope (compile.rs rewrites their scope): the WG invocations share them, and the driver stages
// the operands through shared memory as it sees fit, which is what the extension is for (ggml's
// coopmat2 GEMM works so). WS = 0 keeps subgroup scope, WG = SG: the same kernel on a driver that
// offers only the extension's flexible dimensions (Mesa 26.1's lavapipe), so that CI runs it.
// A [M][K] and B stored N×K ([N][K], a linear layer's weight) are f16, read as the 32-bit words
// their pairs of halves make (compile.rs says why); out [M][N] is f32. M, N and K are multiples
// of FM, FN and FK: the runtime refuses other shapes.
struct Params {
    m: u32,
    n: u32,
    k: u32,
}

var<immediate> p: Params;
@group(0) @binding(0) var<storage, read> a: array<f32>;
@group(0) @binding(1) var<storage, read> b: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>) {
    let row0 = wg.y * FM;
    let col0 = wg.x * FN;
    var acc: FC;
    let stride = p.k / 2u; // strides and offsets count words of two halves
    // Indices and strides through `let`s: naga 30 emits no expression that only a cooperative
    // load's or store's arguments use.
    for (var k0 = 0u; k0 < p.k; k0 += FK) {
        let at = row0 * stride + k0 / 2u;
        let bt = col0 * stride + k0 / 2u;
        let fa = coopLoadT<FA>(&a[at], stride);
        let fb = coopLoad<FB>(&b[bt], stride);
        acc = coopMultiplyAdd(fa, fb, acc);
    }
    let n = p.n;
    let ot = row0 * n + col0;
    coopStoreT(acc, &out[ot], n);
}
