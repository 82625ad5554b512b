// The output side of VK_NV_cooperative_matrix2's GEMM-shaped probes (gemm_cm2.wgsl, conv_cm2.wgsl):
// the epilogue of the other GEMM kernels (gemm_store4.wgsl: alpha, the bias, a fused residual,
// ReLU) on the whole accumulator by the extension's per-element operation, then its conversion to
// f16 and one matrix store. The applied function reads the bias and the residual at its element's
// row and column. GE = 0: the plain product.
const GB: u32 = 4u; // gemm_common.wgsl's GEGLU blocks: unused
@group(0) @binding(2) var<storage, read> bias: array<f16>;
@group(0) @binding(3) var<storage, read_write> out: array<f16>;

alias FH = coop_mat8x8<f16, C>; // the accumulator rounded for the store

// Element (row, col) of the tile whose first element is out[at0], in column col0 of C.
fn finish(row: u32, col: u32, sum: f32, at0: u32, col0: u32) -> f32 {
    var v = p.g.alpha * sum;
    if (p.g.flags & FLAG_BIAS) != 0u {
        v += f32(bias[col0 + col]);
    }
    if (p.g.flags & FLAG_ACCUMULATE) != 0u {
        v += f32(out[at0 + row * p.g.ldc + col]);
    }
    if (p.g.flags & FLAG_RELU) != 0u {
        v = max(v, 0.0);
    }
    return v;
}

// Placeholders of the extension's operations (spirv_rewrite.rs replaces their calls; their
// bodies only give naga a result of the right type).
fn nv_each_at(m: FC, f: f32, at0: u32, col0: u32) -> FC {
    return m;
}

fn nv_convert(m: FC) -> FH {
    var converted: FH;
    return converted;
}

// Stores the accumulator of the tile at out[at0], column col0 of C, finished. Called in uniform
// control flow (it holds a barrier).
fn store_tile(acc: FC, at0: u32, col0: u32) {
    let done = nv_each_at(acc, finish(0u, 0u, 0.0, 0u, 0u), at0, col0);
    // Every residual read before any store: the operation and the store may spread the
    // elements over the invocations differently.
    storageBarrier();
    let rounded = nv_convert(done);
    let ldc = p.g.ldc;
    coopStoreT(rounded, &out[at0], ldc);
}
