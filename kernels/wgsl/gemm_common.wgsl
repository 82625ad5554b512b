// Parameters shared by every GEMM-shaped kernel (matrix product and implicit-GEMM convolution):
// C[batch] = alpha · A[batch]·B[batch] (+ bias) (+ C when accumulating), then ReLU when asked. The A side (`AParams`,
// `RowCtx`, `row_ctx`, `k_ctx`, `load_a*`) comes from the loader file the kernel is built with.
struct GemmParams {
    m: u32,
    n: u32,
    k: u32,
    ldb: u32,
    ldc: u32,
    b_batch: u32,
    c_batch: u32,
    flags: u32,
    alpha: f32,
}

struct Params {
    g: GemmParams,
    a: AParams,
}

var<immediate> p: Params;

const FLAG_BIAS: u32 = 1u;
const FLAG_ACCUMULATE: u32 = 2u;
const FLAG_RELU: u32 = 4u;
