// 2-D pooling of NHWC tensors. OP 0: maximum; padding never wins, as PyTorch pads max pooling with
// −∞. OP 1: mean over the taps inside the image (`count_include_pad=False`, TensorFlow's
// convention, which the FID Inception weights were trained with). A window as large as the
// image is a global average.
@group(0) @binding(0) var<storage, read> x: array<S>;
@group(0) @binding(1) var<storage, read_write> out: array<S>;

struct Params {
    n: u32,
    h: u32,
    w: u32,
    c: u32,
    ho: u32,
    wo: u32,
    kh: u32,
    kw: u32,
    stride: u32,
    pad: u32,
    groups_x: u32,
}

var<immediate> p: Params;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let at = nhwc_position(i, p.ho, p.wo, p.c);
    let oy = at.y;
    let ox = at.z;
    let base = at.x * p.h * p.w * p.c + at.w;
    // The window clipped to the image.
    let y0 = max(i32(oy * p.stride) - i32(p.pad), 0);
    let x0 = max(i32(ox * p.stride) - i32(p.pad), 0);
    let y1 = min(i32(oy * p.stride + p.kh) - i32(p.pad), i32(p.h));
    let x1 = min(i32(ox * p.stride + p.kw) - i32(p.pad), i32(p.w));
    var acc = select(0.0, -3.402823e38, OP == 0u);
    for (var y = y0; y < y1; y++) {
        for (var xx = x0; xx < x1; xx++) {
            let v = f32(x[base + (u32(y) * p.w + u32(xx)) * p.c]);
            if OP == 0u {
                acc = max(acc, v);
            } else {
                acc += v;
            }
        }
    }
    if OP == 1u {
        acc /= f32((y1 - y0) * (x1 - x0));
    }
    out[i] = S(acc);
}
