// The CPU GEMM's B as a uniform texel buffer of four-value texels (RGBA in f32 or f16, which the
// fetch widens), bound where the runtime takes texel operands (`TB` = 1). WGSL has no texel
// buffers: the build declares this 1D texture in naga's SPIR-V as one (spirv_texels.rs).
// Lavapipe before Mesa 26 fetches texels for all lanes at once, where it loads a storage buffer
// in a loop of branches over the lanes.
@group(0) @binding(1) var b: texture_1d<f32>;

// Four values of B from texel `i`, as f32.
fn b_at(i: u32) -> vec4<f32> {
    return textureLoad(b, i32(i), 0);
}
