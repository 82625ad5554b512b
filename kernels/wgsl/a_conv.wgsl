// A operand of an implicit-GEMM convolution (see a_conv_v4.wgsl), read one element at a time so
// any channel count works (the VAE's RGB input has Cin = 3).
@group(0) @binding(0) var<storage, read> a: array<S>;

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
    return RowCtx(
        (t / p.a.ho) * p.a.h * p.a.w * p.a.cin,
        i32((t % p.a.ho) * p.a.stride) - i32(p.a.pad_y),
        i32((m % p.a.wo) * p.a.stride) - i32(p.a.pad_x),
    );
}

fn k_ctx(k: u32) -> KCtx {
    let kk = min(k, p.g.k - 1u);
    let t = kk / p.a.cin;
    return KCtx(i32(t / p.a.kw), i32(t % p.a.kw), kk % p.a.cin);
}

fn load_a1(r: RowCtx, k: KCtx) -> f32 {
    let y = r.y + k.dy;
    let x = r.x + k.dx;
    let inside = y >= 0 && y < i32(p.a.h) && x >= 0 && x < i32(p.a.w);
    let yc = u32(clamp(y, 0, i32(p.a.h) - 1));
    let xc = u32(clamp(x, 0, i32(p.a.w) - 1));
    return select(0.0, f32(a[r.base + (yc * p.a.w + xc) * p.a.cin + k.ci]), inside);
}
