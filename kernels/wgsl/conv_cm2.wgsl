// A convolution's implicit GEMM through VK_NV_cooperative_matrix2, for `bench kernels` and
// `VKDIFF_CONV=cm2` (a probe, as gemm_cm2.wgsl is: it takes the convolution's place nowhere
// unasked until a GPU has timed it against gemm_coop.wgsl's conv_coop). Each workgroup holds one
// FM×FN accumulator, FM output pixels (batch folded in) by FN output channels, and walks
// K = (ky·KW + kx)·Cin + ci in steps of FK. A matrix load reads a strided block, which a
// convolution's columns are not, so A's FM×FK slice is gathered from the NHWC input into
// workgroup memory (conv_taps.wgsl's taps, zero in the padding; ggml's coopmat2 convolution loads
// through the extension's tensor addressing instead, which no driver here offers to test); the
// next step's units are read into registers while the matrices work on this one. B's FK×FN slice
// (the OHWI weight, [Cout][K]) is one block and loads straight from device memory, the driver
// staging it as gemm_cm2.wgsl's operands are; cm2_store.wgsl finishes and stores the tile.
// WS = 1 gives the matrices workgroup scope, shared by WG invocations (NVIDIA's drivers); WS = 0
// subgroup scope on a workgroup of one subgroup (Mesa 26.1's lavapipe, for CI). Operands are f16,
// the input (a_conv_v4.wgsl) and the weight read as their bits; M, Cout and K are multiples of
// FM, FN and FK and Cin of UW: the runtime refuses the rest.
@group(0) @binding(1) var<storage, read> b: array<f32>;

const UK: u32 = FK / UW; // units along a row of the A tile
const STEP: u32 = WG / UK; // tile rows between an invocation's units
const PA: u32 = FM * FK / (UW * WG); // an invocation's units a step
const LDA: u32 = FK + 8u; // A tile rows in halves: a multiple of 8 (16 bytes, as matrix loads need)
const_assert WG % UK == 0u;
const_assert PA * UW * WG == FM * FK;

var<workgroup> a_tile: array<Words, FM * LDA / UW>;

// This invocation's units of the step whose columns kc walks (tile rows tr + STEP·i), zero where
// a tap falls in the padding.
fn fetch(rows: ptr<function, array<RowCtx, PA>>, units: ptr<function, array<Words, PA>>, kc: KCtx) {
    // #unroll I FM*FK/UW/WG
    (*units)[I] = bitcast<Words>(select(Unit(), a_unit((*rows)[I], kc), a_unit_inside((*rows)[I], kc)));
    // #end
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let row0 = wg.y * FM;
    let col0 = wg.x * FN;
    let tu = t % UK;
    let tr = t / UK;
    var rows: array<RowCtx, PA>;
    // #unroll I FM*FK/UW/WG
    rows[I] = row_ctx(0u, row0 + tr + STEP * I);
    // #end
    var units: array<Words, PA>;
    let step = k_step(FK);
    var walk = k_walk(UW * tu);
    fetch(&rows, &units, k_at(walk));
    var acc: FC;
    let stride = p.g.k / 2u; // the weight's rows in words of two halves
    for (var k0 = 0u; k0 < p.g.k; k0 += FK) {
        // #unroll I FM*FK/UW/WG
        a_tile[(tr + STEP * I) * (LDA / UW) + tu] = units[I];
        // #end
        workgroupBarrier();
        // The last step fetches columns past K: their taps read inside the input (conv_taps.wgsl)
        // and nothing stores them.
        walk = k_next(walk, step);
        fetch(&rows, &units, k_at(walk));
        // Offsets through `let`s: naga 30 emits no expression that only a cooperative load uses.
        let bt = col0 * stride + k0 / 2u;
        let fa = coopLoadT<FA>(&a_tile[0], LDA / UW);
        let fb = coopLoad<FB>(&b[bt], stride);
        acc = coopMultiplyAdd(fa, fb, acc);
        workgroupBarrier();
    }
    store_tile(acc, row0 * p.g.ldc + col0, col0);
}
