// Shared by the convolution A loaders: row m is an output pixel of an NHWC input (batch folded
// into M), column k = (ky·KW + kx)·Cin + ci.
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

// A row's output pixel: where its receptive field's corner (y, x) would sit in the input, and
// that pixel's element index (both may lie outside the image; only taps inside are read).
struct RowCtx {
    at: i32,
    y: i32,
    x: i32,
}

// A column's tap (dy, dx) and channel ci, and its element offset from the row's corner. Columns
// past K are not clamped: their taps still read inside the tensor (tap), and the kernels mask
// their values.
struct KCtx {
    dy: i32,
    dx: i32,
    ci: u32,
    off: i32,
}

fn row_ctx(batch: u32, row: u32) -> RowCtx {
    let m = min(row, p.g.m - 1u);
    let t = m / p.a.wo;
    let y = i32((t % p.a.ho) * p.a.stride) - i32(p.a.pad_y);
    let x = i32((m % p.a.wo) * p.a.stride) - i32(p.a.pad_x);
    let base = (t / p.a.ho) * p.a.h * p.a.w * p.a.cin;
    return RowCtx(i32(base) + (y * i32(p.a.w) + x) * i32(p.a.cin), y, x);
}

fn tap_ctx(dy: i32, dx: i32, ci: u32) -> KCtx {
    return KCtx(dy, dx, ci, (dy * i32(p.a.w) + dx) * i32(p.a.cin) + i32(ci));
}

fn k_ctx(k: u32) -> KCtx {
    let t = k / p.a.cin;
    return tap_ctx(i32(t / p.a.kw), i32(t % p.a.kw), k % p.a.cin);
}

// Walking K a step of s columns at a time (gemm_coop.wgsl) takes no division: the step splits
// once into channels, taps across and taps down, and each walk carries its channels into taps and
// its taps into rows (at most once each: the step's parts are below cin and kw).
struct KStep {
    ci: u32,
    dx: i32,
    dy: i32,
    off: i32, // the step's element offset, without carries
    wrap: i32, // what a carry from taps across into rows adds to it
}

alias KWalk = KCtx;

fn k_walk(k: u32) -> KWalk {
    return k_ctx(k);
}

fn k_step(s: u32) -> KStep {
    let taps = s / p.a.cin;
    let across = tap_ctx(i32(taps / p.a.kw), i32(taps % p.a.kw), s % p.a.cin);
    return KStep(across.ci, across.dx, across.dy, across.off, i32(p.a.cin) * (i32(p.a.w) - i32(p.a.kw)));
}

fn k_next(k: KWalk, s: KStep) -> KWalk {
    let ci = k.ci + s.ci;
    let into_tap = ci >= p.a.cin;
    let dx = k.dx + s.dx + i32(into_tap);
    let into_row = dx >= i32(p.a.kw);
    return KCtx(
        k.dy + s.dy + i32(into_row),
        select(dx, dx - i32(p.a.kw), into_row),
        select(ci, ci - p.a.cin, into_tap),
        k.off + s.off + select(0, s.wrap, into_row),
    );
}

fn k_at(k: KWalk) -> KCtx {
    return k;
}

// Where tap (r, k) reads the input, and whether it falls inside (else it is zero padding, and
// the read goes to element 0, in bounds).
struct Tap {
    at: u32,
    inside: bool,
}

fn tap(r: RowCtx, k: KCtx) -> Tap {
    let inside = (u32(r.y + k.dy) < p.a.h) & (u32(r.x + k.dx) < p.a.w);
    return Tap(select(0u, u32(r.at + k.off), inside), inside);
}
