// Element-wise kernels: 64 invocations per workgroup, workgroups spread over x and y (see
// runtime ops::grid); `p.groups_x` is the x extent. Returns the flat element index.
fn element_index(wg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * p.groups_x + wg.x) * 64u + lid;
}

// Flat element i of NHWC images of h × w pixels and c channels as (image, y, x, channel).
fn nhwc_position(i: u32, h: u32, w: u32, c: u32) -> vec4<u32> {
    let pix = i / c;
    let rest = pix / w;
    return vec4<u32>(rest / h, rest % h, pix % w, i % c);
}
