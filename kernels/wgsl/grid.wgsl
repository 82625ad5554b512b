// Element-wise kernels: 64 invocations per workgroup, workgroups spread over x and y (see
// runtime ops::grid); `p.groups_x` is the x extent. Returns the flat element index.
fn element_index(wg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * p.groups_x + wg.x) * 64u + lid;
}
