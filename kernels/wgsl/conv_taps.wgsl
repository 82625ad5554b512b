// Shared by the convolution A loaders: row m is an output pixel of an NHWC input (batch folded
// into M), column k = (ky·KW + kx)·Cin + ci. The loader file defines A_VEC (elements per load).
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
    // Clamped so lanes past K still read inside the tensor (their values are never used).
    let kk = min(k, p.g.k - A_VEC);
    let t = kk / p.a.cin;
    return KCtx(i32(t / p.a.kw), i32(t % p.a.kw), kk % p.a.cin);
}

// Where tap (r, k) reads the input, and whether it falls inside (else it is zero padding).
struct Tap {
    at: u32,
    inside: bool,
}

fn tap(r: RowCtx, k: KCtx) -> Tap {
    let y = r.y + k.dy;
    let x = r.x + k.dx;
    let inside = (y >= 0) & (y < i32(p.a.h)) & (x >= 0) & (x < i32(p.a.w));
    let yc = u32(clamp(y, 0, i32(p.a.h) - 1));
    let xc = u32(clamp(x, 0, i32(p.a.w) - 1));
    return Tap(r.base + (yc * p.a.w + xc) * p.a.cin + k.ci, inside);
}
