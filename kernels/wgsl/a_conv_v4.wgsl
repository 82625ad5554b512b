// A operand of an implicit-GEMM convolution: row m is an output pixel of an NHWC input
// (batch folded into M), column k = (ky·KW + kx)·Cin + ci. Read as vec4 along Cin (Cin % 4 = 0).
@group(0) @binding(0) var<storage, read> a: array<vec4<S>>;

struct AParams {
    h: u32,
    w: u32,
    cin: u32,
    ho: u32,
    wo: u32,
    kw: u32,
    stride: u32,
    pad_y: u32,
    pad_x: u32,
}

struct RowCtx {
    base: u32,
    y: i32,
    x: i32,
}

struct KCtx {
    dy: i32,
    dx: i32,
    ci: u32,
}

fn row_ctx(batch: u32, row: u32) -> RowCtx {
    let m = min(row, p.g.m - 1u);
    let t = m / p.a.wo;
    let oy = t % p.a.ho;
    let ox = m % p.a.wo;
    return RowCtx(
        (t / p.a.ho) * p.a.h * p.a.w * p.a.cin,
        i32(oy * p.a.stride) - i32(p.a.pad_y),
        i32(ox * p.a.stride) - i32(p.a.pad_x),
    );
}

fn k_ctx(k: u32) -> KCtx {
    let kk = min(k, p.g.k - 4u);
    let t = kk / p.a.cin;
    return KCtx(i32(t / p.a.kw), i32(t % p.a.kw), kk % p.a.cin);
}

fn load_a(r: RowCtx, k: KCtx) -> vec4<f32> {
    let y = r.y + k.dy;
    let x = r.x + k.dx;
    let inside = y >= 0 && y < i32(p.a.h) && x >= 0 && x < i32(p.a.w);
    let yc = u32(clamp(y, 0, i32(p.a.h) - 1));
    let xc = u32(clamp(x, 0, i32(p.a.w) - 1));
    let v = vec4<f32>(a[(r.base + (yc * p.a.w + xc) * p.a.cin + k.ci) / 4u]);
    return select(vec4<f32>(0.0), v, inside);
}
