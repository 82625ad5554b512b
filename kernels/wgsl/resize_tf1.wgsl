// Bilinear resize of an 8-bit image as TensorFlow 1.x computes it (align_corners=False, no half-pixel
// centres): output pixel d samples the input at d·(in/out), its far neighbour clamped to the last
// row or column. This is the resize the FID Inception was defined with, which torch-fidelity
// reproduces; then out = (v + shift)·scale (torch-fidelity: (v − 128)/128). The image is its
// bytes (H·W·C, row-major), four to a word: a 12-megapixel photo binds as 36 MB, not 144. It lands
// as image `first` of the NHWC output, so images of other sizes share one batch. Output channels
// past the input's are zero: RGB padded to 4 channels takes the vectorised convolution.
@group(0) @binding(0) var<storage, read> x: array<u32>;
@group(0) @binding(1) var<storage, read_write> out: array<S>;

struct Params {
    n: u32,
    h: u32,
    w: u32,
    c: u32,
    c_out: u32,
    ho: u32,
    wo: u32,
    scale_y: f32,
    scale_x: f32,
    shift: f32,
    scale: f32,
    first: u32,
    groups_x: u32,
}

var<immediate> p: Params;

fn byte_at(i: u32) -> f32 {
    return f32((x[i / 4u] >> (8u * (i % 4u))) & 0xffu);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let pos = nhwc_position(i, p.ho, p.wo, p.c_out);
    let at = p.first * p.ho * p.wo * p.c_out + i;
    if pos.w >= p.c {
        out[at] = S(0.0);
        return;
    }
    let gy = f32(pos.y) * p.scale_y;
    let gx = f32(pos.z) * p.scale_x;
    let y0 = u32(gy);
    let x0 = u32(gx);
    let y1 = min(y0 + 1u, p.h - 1u);
    let x1 = min(x0 + 1u, p.w - 1u);
    let dy = gy - f32(y0);
    let dx = gx - f32(x0);
    let v00 = byte_at((y0 * p.w + x0) * p.c + pos.w);
    let v01 = byte_at((y0 * p.w + x1) * p.c + pos.w);
    let v10 = byte_at((y1 * p.w + x0) * p.c + pos.w);
    let v11 = byte_at((y1 * p.w + x1) * p.c + pos.w);
    let top = v00 + (v01 - v00) * dx;
    let bottom = v10 + (v11 - v10) * dx;
    out[at] = S((top + (bottom - top) * dy + p.shift) * p.scale);
}
