// Winograd F(2×2, 3×3), step 1 of 3 (runtime ops/winograd.rs): each invocation takes one 4×4
// input tile (tiles step 2 along each axis, reading zeros past the image: the padding) at four
// channels and writes Bᵀ·d·B, the tile's 16 transformed values, one per plane of v
// [16][tiles][C]. Counts are in units of four channels (unit_4.wgsl); the tiles are those from
// `t0` on (winograd_tiles.wgsl).
@group(0) @binding(0) var<storage, read> x: array<U>;
@group(0) @binding(1) var<storage, read_write> v: array<U>;

struct Params {
    n: u32,
    h: u32,
    w: u32,
    c: u32,
    tiles_h: u32,
    tiles_w: u32,
    t0: u32,
    pad_top: u32,
    pad_left: u32,
    plane: u32,
    groups_x: u32,
}

var<immediate> p: Params;

// Bᵀ·(a, b, c, d): B = the F(2, 3) input transform.
fn input_rows(a: vec4<f32>, b: vec4<f32>, c: vec4<f32>, d: vec4<f32>) -> array<vec4<f32>, 4> {
    return array<vec4<f32>, 4>(a - c, b + c, c - b, b - d);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = element_index(wg, lid);
    if i >= p.n {
        return;
    }
    let ch = i % p.c;
    let at = tile_at(i);
    let image = at.x;
    // Signed: the first tile row and column start in the padding.
    let y0 = i32(at.y) - i32(p.pad_top);
    let x0 = i32(at.z) - i32(p.pad_left);
    var d: array<vec4<f32>, 16>;
    for (var r = 0; r < 4; r++) {
        for (var s = 0; s < 4; s++) {
            let y = y0 + r;
            let xx = x0 + s;
            var value = vec4<f32>(0.0);
            if (y >= 0) & (y < i32(p.h)) & (xx >= 0) & (xx < i32(p.w)) {
                value = widen(x[((image * p.h + u32(y)) * p.w + u32(xx)) * p.c + ch]);
            }
            d[4 * r + s] = value;
        }
    }
    // Bᵀ·d down the columns, then ·B along the rows.
    var t: array<vec4<f32>, 16>;
    for (var s = 0; s < 4; s++) {
        let col = input_rows(d[s], d[4 + s], d[8 + s], d[12 + s]);
        for (var r = 0; r < 4; r++) {
            t[4 * r + s] = col[r];
        }
    }
    for (var r = 0; r < 4; r++) {
        let out = input_rows(t[4 * r], t[4 * r + 1], t[4 * r + 2], t[4 * r + 3]);
        for (var s = 0; s < 4; s++) {
            v[u32(4 * r + s) * p.plane + i] = narrow(out[s]);
        }
    }
}
