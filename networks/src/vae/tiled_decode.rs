//! diffusers' tiled VAE decode (`AutoencoderKL.enable_tiling`): the latent is cut into
//! overlapping square tiles, each decoded alone (so a decode's memory is one tile's), and each
//! tile's first rows and columns are blended linearly into its neighbours above and to the left,
//! in diffusers' order and arithmetic. Its GroupNorms see one tile's statistics, so the image
//! differs from the whole decode (slightly for trained VAEs); this is what diffusers users get.

use crate::error::{Error, Result};
use crate::vae::{AutoencoderKl, VaeConfig};
use vkdiff_runtime::Dtype;

/// diffusers' fixed `tile_overlap_factor`.
const OVERLAP: f64 = 0.25;

/// The tile geometry of one tiled decode, in diffusers' terms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VaeTiling {
    /// `tile_sample_min_size`: a tile's side in pixels.
    pub tile: usize,
}

/// A decoded tile: NHWC rows of `width` pixels of `channels` values, for `batch` images.
struct Tile {
    data: Vec<f32>,
    batch: usize,
    height: usize,
    width: usize,
    channels: usize,
}

impl Tile {
    fn at(&self, n: usize, y: usize, x: usize) -> usize {
        ((n * self.height + y) * self.width + x) * self.channels
    }
}

impl VaeConfig {
    /// Device memory the activations of a decode in `dtype` take, for `batch` images of `height`×`width` pixels
    /// (a tile's, when tiled): per output pixel 4·(c₀ + c₁) + c₀ values of the first two levels'
    /// channels, and a tenth more. Measured on lavapipe (peak less weights, linear in pixels):
    /// SDXL's VAE [128, 256, …] 1,547 values per pixel (f32 at 128² and 256², f16 at 256²), the
    /// tiny test VAE [32, 32, …] 289 (64² to 256², batch 1 and 2); this gives 1,830 and 317.
    /// Those were measured with direct convolutions; CPU devices run Winograd's, whose scratch
    /// (bounded by `winograd_scratch_bytes` for the widest channels) comes on top.
    pub fn decode_bytes(&self, dtype: Dtype, batch: usize, height: usize, width: usize) -> u64 {
        let ch = &self.block_out_channels;
        let (c0, c1) = (ch[0], *ch.get(1).unwrap_or(&ch[0]));
        let values = (4 * (c0 + c1) + c0) as f64 * 1.1;
        let tiles = batch * height.div_ceil(2) * width.div_ceil(2);
        let widest = ch.iter().copied().max().unwrap_or(c0);
        (values * (batch * height * width * vkdiff_runtime::dtype_size(dtype)) as f64) as u64
            + vkdiff_runtime::ops::winograd_scratch_bytes(widest, tiles, dtype)
    }

    /// The largest single activation of a decode (one buffer, held to `maxMemoryAllocationSize`):
    /// the second level's channels at full resolution.
    pub fn decode_largest_tensor(&self, dtype: Dtype, batch: usize, height: usize, width: usize) -> u64 {
        let ch = &self.block_out_channels;
        let c1 = *ch.get(1).unwrap_or(&ch[0]);
        (batch * height * width * c1 * vkdiff_runtime::dtype_size(dtype)) as u64
    }

    /// Whether `tiling` tiles a latent of `h`×`w`, as diffusers decides: only when a side passes
    /// the latent tile.
    pub fn tiles(&self, tiling: VaeTiling, h: usize, w: usize) -> bool {
        let latent = tiling.tile / self.downscale();
        h > latent || w > latent
    }

    /// The checks on a tile size, before any work: a multiple of 4 latents, so diffusers' step
    /// (three quarters of a tile) and its crop (a tile less its blend) are the same length and
    /// the tiles rebuild the image exactly.
    pub fn check_tiling(&self, tiling: VaeTiling) -> Result<()> {
        let unit = 4 * self.downscale();
        if tiling.tile == 0 || !tiling.tile.is_multiple_of(unit) {
            return Err(Error::Config(format!(
                "a VAE tile must be a positive multiple of {unit} pixels, not {}",
                tiling.tile
            )));
        }
        Ok(())
    }
}

impl AutoencoderKl {
    /// [`AutoencoderKl::decode`] in tiles of `tiling` (the whole decode when the latent fits one).
    pub fn decode_tiled(
        &self,
        latents: &[f32],
        shape: [usize; 4],
        tiling: VaeTiling,
    ) -> Result<(Vec<f32>, [usize; 4])> {
        self.config().check_tiling(tiling)?;
        let [b, h, w, c] = shape;
        if !self.config().tiles(tiling, h, w) {
            return self.decode(latents, shape);
        }
        let s = self.config().downscale();
        let latent_tile = tiling.tile / s;
        let step = (latent_tile as f64 * (1.0 - OVERLAP)) as usize;
        let blend = (tiling.tile as f64 * OVERLAP) as usize;
        let keep = tiling.tile - blend;
        let mut rows: Vec<Vec<Tile>> = Vec::new();
        for y0 in (0..h).step_by(step) {
            let mut row = Vec::new();
            for x0 in (0..w).step_by(step) {
                let (th, tw) = ((h - y0).min(latent_tile), (w - x0).min(latent_tile));
                let mut part = Vec::with_capacity(b * th * tw * c);
                for n in 0..b {
                    for y in y0..y0 + th {
                        let start = ((n * h + y) * w + x0) * c;
                        part.extend_from_slice(&latents[start..start + tw * c]);
                    }
                }
                let (data, [_, height, width, channels]) = self.decode(&part, [b, th, tw, c])?;
                row.push(Tile { data, batch: b, height, width, channels });
            }
            rows.push(row);
        }
        // Blended in place in diffusers' order: a tile takes its already-blended neighbours.
        for i in 0..rows.len() {
            for j in 0..rows[i].len() {
                if i > 0 {
                    let (above, here) = rows.split_at_mut(i);
                    blend_rows(&above[i - 1][j], &mut here[0][j], blend);
                }
                if j > 0 {
                    let (left, here) = rows[i].split_at_mut(j);
                    blend_columns(&left[j - 1], &mut here[0], blend);
                }
            }
        }
        let channels = rows[0][0].channels;
        let (height, width) = (h * s, w * s);
        let mut out = vec![0f32; b * height * width * channels];
        let mut y = 0;
        for row in &rows {
            let mut x = 0;
            for tile in row {
                let (kh, kw) = (tile.height.min(keep), tile.width.min(keep));
                for n in 0..b {
                    for ty in 0..kh {
                        let src = tile.at(n, ty, 0);
                        let dst = ((n * height + y + ty) * width + x) * channels;
                        out[dst..dst + kw * channels].copy_from_slice(&tile.data[src..src + kw * channels]);
                    }
                }
                x += kw;
            }
            y += row[0].height.min(keep);
        }
        Ok((out, [b, height, width, channels]))
    }
}

/// diffusers' weights for blend row (or column) `k` of `extent`: the earlier tile's share, then
/// this one's, each a Python float cast to the tensor's f32.
fn weights(k: usize, extent: usize) -> (f32, f32) {
    let t = k as f64 / extent as f64;
    ((1.0 - t) as f32, t as f32)
}

/// diffusers' `blend_v`: `b`'s first rows fade in from `a`'s last.
fn blend_rows(a: &Tile, b: &mut Tile, blend: usize) {
    let extent = blend.min(a.height).min(b.height);
    for n in 0..b.batch {
        for k in 0..extent {
            let (wa, wb) = weights(k, extent);
            let (ra, rb) = (a.at(n, a.height - extent + k, 0), b.at(n, k, 0));
            for v in 0..b.width * b.channels {
                b.data[rb + v] = a.data[ra + v] * wa + b.data[rb + v] * wb;
            }
        }
    }
}

/// diffusers' `blend_h`: `b`'s first columns fade in from `a`'s last.
fn blend_columns(a: &Tile, b: &mut Tile, blend: usize) {
    let extent = blend.min(a.width).min(b.width);
    for n in 0..b.batch {
        for y in 0..b.height {
            for k in 0..extent {
                let (wa, wb) = weights(k, extent);
                let (pa, pb) = (a.at(n, y, a.width - extent + k), b.at(n, y, k));
                for ch in 0..b.channels {
                    b.data[pb + ch] = a.data[pa + ch] * wa + b.data[pb + ch] * wb;
                }
            }
        }
    }
}
