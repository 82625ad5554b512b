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

// GE = 1 (linear layers, B stored N×K) fuses GEGLU into the product: its N columns pair values
// with their gates. Product column n is B's row b_row(n): blocks of GB value rows (GB is the
// kernel's own) alternate with the matching gate rows N/2 further on, so that each value meets
// its gate in one invocation's epilogue, which writes value·GELU_erf(gate) (biases added first)
// at C's column out_col(n) of N/2. GE = 0: the plain product.
fn b_row(n: u32) -> u32 {
    if GE == 0u {
        return n;
    }
    let within = n % (2u * GB);
    return select(0u, p.g.n / 2u, within >= GB) + (n / (2u * GB)) * GB + within % GB;
}

// C's column of product column n, a value column of a GE = 1 product.
fn out_col(n: u32) -> u32 {
    return (n / (2u * GB)) * GB + n % GB;
}
