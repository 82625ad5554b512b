// The build's rewrite of naga's SPIR-V for kernels that read an operand from a uniform texel
// buffer, which WGSL cannot declare: they declare a sampled 1D texture and read it with
// `textureLoad` at level 0. Included by compile.rs.

/// `words` with every 1D sampled image made a buffer image: the image type's dimension becomes
/// Buffer, each `OpImageFetch` loses its level-of-detail operand (a buffer has no levels), and the
/// Sampled1D capability becomes SampledBuffer. Anything else about images (sampling, queries,
/// other operands) is an error: these kernels only fetch.
fn texel_buffers(words: &[u32]) -> Result<Vec<u32>, String> {
    const OP_CAPABILITY: u32 = 17;
    const OP_TYPE_IMAGE: u32 = 25;
    const OP_IMAGE_FETCH: u32 = 95;
    const SAMPLED_1D: u32 = 43;
    const SAMPLED_BUFFER: u32 = 46;
    const DIM_1D: u32 = 0;
    const DIM_BUFFER: u32 = 5;
    const LOD: u32 = 0x2;
    let mut out = words.get(..5).ok_or("SPIR-V shorter than its header")?.to_vec();
    let (mut images, mut fetches) = (0, 0);
    for inst in instructions(words)? {
        match (inst[0] & 0xffff, inst.len()) {
            (OP_CAPABILITY, 2) if inst[1] == SAMPLED_1D => out.extend([inst[0], SAMPLED_BUFFER]),
            (OP_TYPE_IMAGE, 9) if inst[3] == DIM_1D && inst[7] == 1 => {
                images += 1;
                out.extend([inst[0], inst[1], inst[2], DIM_BUFFER]);
                out.extend_from_slice(&inst[4..]);
            }
            (OP_TYPE_IMAGE, _) => return Err("an image other than a sampled 1D one".into()),
            (OP_IMAGE_FETCH, 7) if inst[5] == LOD => {
                fetches += 1;
                out.extend([(5 << 16) | OP_IMAGE_FETCH, inst[1], inst[2], inst[3], inst[4]]);
            }
            (op, _) if (OP_IMAGE_FETCH - 8..=OP_IMAGE_FETCH + 12).contains(&op) => {
                return Err(format!("image instruction {op} other than a fetch at a level"));
            }
            _ => out.extend_from_slice(inst),
        }
    }
    if images == 0 || fetches == 0 {
        return Err(format!("{images} 1D images and {fetches} fetches: nothing to read from texels"));
    }
    Ok(out)
}
