// The tiles of Winograd's transforms (winograd_input.wgsl, winograd_output.wgsl): invocation i
// takes unit i % c of the channels of tile t0 + i / c, the tiles numbered image by image, row by
// row, each 2×2 outputs. Returns the tile's image and its first output row and column.
fn tile_at(i: u32) -> vec3<u32> {
    let tile = p.t0 + i / p.c;
    let rows = tile / p.tiles_w;
    return vec3<u32>(rows / p.tiles_h, 2u * (rows % p.tiles_h), 2u * (tile % p.tiles_w));
}
