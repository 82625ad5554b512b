//! The VAE decode's memory plan, made once before any denoising: whole, or in diffusers'
//! tiles, as `--vae-tiling` says and the device's free memory allows (VKDIFF_MEMORY_BUDGET,
//! VK_EXT_memory_budget, or the heap), so a decode that cannot fit fails before the steps run,
//! not after them.

use crate::error::{Error, Result};
use crate::sdxl::Sdxl;
use crate::settings::VaeTilingSetting;
use vkdiff_networks::{VaeConfig, VaeTiling};
use vkdiff_runtime::{Dtype, MemoryRoom};
use vkdiff_setting::Message;

/// The smallest tile `auto` takes: below it the blends are a large part of each tile.
const SMALLEST_AUTO_TILE: usize = 128;

/// What the plan chose and why.
#[derive(Clone, Copy, Debug)]
pub struct VaePlan {
    pub tiling: Option<VaeTiling>,
    /// Activation memory of the whole decode and of the decode as planned.
    pub whole_bytes: u64,
    pub planned_bytes: u64,
    pub room: MemoryRoom,
}

impl VaePlan {
    /// One line for the log when the plan tiles.
    pub fn note(&self, width: usize, height: usize) -> Option<String> {
        let tile = self.tiling?.tile;
        Some(format!(
            "VAE: {width}×{height} decodes in {tile}-px tiles, {} each (the whole decode needs {}; {} free by {})",
            mib(self.planned_bytes),
            mib(self.whole_bytes),
            mib(self.room.free),
            self.room.source
        ))
    }
}

fn mib(bytes: u64) -> String {
    format!("{} MiB", bytes.div_ceil(1 << 20))
}

impl VaePlan {
    /// Plans the decodes of `batch` images of `width`×`height` pixels by a VAE of `config` in
    /// `dtype`, as `setting` says and `room` allows (each buffer within `max_allocation`, 0 for
    /// no limit).
    #[allow(clippy::too_many_arguments)]
    pub fn choose(
        config: &VaeConfig,
        dtype: Dtype,
        room: MemoryRoom,
        max_allocation: u64,
        setting: VaeTilingSetting,
        batch: usize,
        width: usize,
        height: usize,
    ) -> Result<VaePlan> {
        let usable = usable(room);
        let s = config.downscale();
        let (lh, lw) = (height / s, width / s);
        let need = |tile: Option<usize>| {
            let (h, w) = tile.map_or((height, width), |t| (t.min(height), t.min(width)));
            (config.decode_bytes(dtype, batch, h, w), config.decode_largest_tensor(dtype, batch, h, w))
        };
        let fits = |tile: Option<usize>| {
            let (bytes, largest) = need(tile);
            bytes <= usable && (max_allocation == 0 || largest <= max_allocation)
        };
        let whole_bytes = need(None).0;
        let plan = |tile: Option<usize>| {
            let tiling = tile.map(|tile| VaeTiling { tile }).filter(|&t| config.tiles(t, lh, lw));
            VaePlan { tiling, whole_bytes, planned_bytes: need(tiling.map(|t| t.tile)).0, room }
        };
        let refused = |what: String| Error::Setting(Message::setting("vae_tiling").then(what));
        Ok(match setting {
            VaeTilingSetting::Off if fits(None) => plan(None),
            VaeTilingSetting::Off => {
                return Err(refused(format!(
                    " off: the VAE decode of {batch}×{width}×{height} needs {} of device memory, {} free by {}; \
                    auto decodes in tiles that fit",
                    mib(whole_bytes),
                    mib(usable),
                    room.source
                )))
            }
            VaeTilingSetting::On | VaeTilingSetting::Pixels(_) => {
                let tile = match setting {
                    VaeTilingSetting::Pixels(tile) => tile,
                    _ => config.tile_sample_size(),
                };
                let tiling = VaeTiling { tile };
                config.check_tiling(tiling).map_err(|e| refused(format!(" {tile}: {e}")))?;
                plan(Some(tile))
            }
            VaeTilingSetting::Auto if fits(None) => plan(None),
            VaeTilingSetting::Auto => {
                // diffusers' tile, then halves of it, down to 128 px (or the VAE's own smaller tile).
                let unit = 4 * s;
                let largest = (config.tile_sample_size() / unit * unit).max(unit);
                let smallest = SMALLEST_AUTO_TILE.min(largest).max(unit);
                let tiles: Vec<usize> = std::iter::successors(Some(largest), |t| Some(t / 2 / unit * unit))
                    .take_while(|&t| t >= smallest)
                    .filter(|&t| t < height.max(width))
                    .collect();
                match tiles.iter().find(|&&t| fits(Some(t))) {
                    Some(&tile) => plan(Some(tile)),
                    None => {
                        let tried = tiles
                            .last()
                            .map_or(String::new(), |&t| format!(" and {} in {t}-px tiles", mib(need(Some(t)).0)));
                        return Err(refused(format!(
                            " auto: the VAE decode of {batch}×{width}×{height} needs {} whole{tried}, {} free by {}; \
                            a smaller image or batch needs less",
                            mib(whole_bytes),
                            mib(usable),
                            room.source
                        )));
                    }
                }
            }
        })
    }
}

impl Sdxl {
    /// Plans the decodes of `batch` images of `width`×`height` pixels as `setting` says and the
    /// device's free memory allows ([`VaePlan::choose`]), and keeps the plan for [`Sdxl::decode`].
    pub fn plan_vae(
        &mut self,
        setting: VaeTilingSetting,
        batch: usize,
        width: usize,
        height: usize,
    ) -> Result<VaePlan> {
        let (config, dtype) = (self.vae.config(), self.vae.dtype());
        let room = self.ctx.memory_room();
        let max_allocation = self.ctx.info().max_allocation;
        let chosen = VaePlan::choose(config, dtype, room, max_allocation, setting, batch, width, height)?;
        self.vae_plan = Some(chosen);
        Ok(chosen)
    }

    /// The tiles decodes take (None: whole), as [`Sdxl::plan_vae`] chose.
    pub fn vae_tiling(&self) -> Option<VaeTiling> {
        self.vae_plan.and_then(|p| p.tiling)
    }

    /// Whether the planned decode fits in the memory free now, beside what was taken since the
    /// plan (a recorded denoiser kept for the next batch).
    pub fn decode_fits_now(&self) -> bool {
        self.vae_plan.is_none_or(|plan| usable(self.ctx.memory_room()) >= plan.planned_bytes)
    }
}

/// What a plan may take of `room`: a twentieth of the budget stays free (allocator blocks,
/// staging, the latents).
fn usable(room: MemoryRoom) -> u64 {
    room.free.saturating_sub(room.budget / 20)
}
