#!/usr/bin/env python3
"""diffusers' tiled VAE decode (AutoencoderKL.enable_tiling / tiled_decode) on the tiny SDXL VAE of
tests/fixtures/pipeline/tiny-sdxl, for vkdiff's tiled decode test (networks/tests/networks/vae_tiling.rs).

Versions used to write the committed fixture: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
safetensors 0.8.0.
Setup and rerun (the tiny pipeline must exist; its VAE is loaded, not regenerated):
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch diffusers safetensors
  /tmp/ref/bin/python tools/make_vae_tiling_fixtures.py [--pipeline tests/fixtures/pipeline/tiny-sdxl]
      [--out tests/fixtures/pipeline/vae_tiling.safetensors]

Writes one safetensors file (float32; metadata "cases" as JSON): a seeded latent 2x4x12x16 (NCHW, as
diffusers' decode takes it, already divided by the scaling factor), its whole decode, and its tiled decode
for two tile sizes: the config's sample_size (64 px: 8-latent tiles, 6-latent steps, 16-px blends) and
32 px (set as diffusers users set it, vae.tile_sample_min_size = 32, vae.tile_latent_min_size = 4).
"""
import argparse
import json

import torch
from diffusers import AutoencoderKL
from safetensors.torch import save_file


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--pipeline", default="tests/fixtures/pipeline/tiny-sdxl")
    p.add_argument("--out", default="tests/fixtures/pipeline/vae_tiling.safetensors")
    args = p.parse_args()
    vae = AutoencoderKL.from_pretrained(args.pipeline, subfolder="vae", torch_dtype=torch.float32).eval()
    latent = torch.randn(2, 4, 12, 16, generator=torch.Generator().manual_seed(77))
    tensors = {"latent": latent}
    cases = []
    with torch.no_grad():
        tensors["whole"] = vae.decode(latent).sample
        vae.enable_tiling()
        for tile in (vae.config.sample_size, 32):
            vae.tile_sample_min_size = tile
            vae.tile_latent_min_size = tile // 2 ** (len(vae.config.block_out_channels) - 1)
            name = f"tiled_{tile}"
            tensors[name] = vae.decode(latent).sample
            diff = (tensors[name] - tensors["whole"]).abs().max().item()
            print(f"{name}: {tuple(tensors[name].shape)}, max difference from the whole decode {diff:.3e}")
            cases.append(dict(tensor=name, tile_sample_size=tile, tile_latent_size=vae.tile_latent_min_size,
                              overlap=vae.tile_overlap_factor))
    meta = dict(cases=json.dumps(cases), made_by="tools/make_vae_tiling_fixtures.py")
    save_file({k: v.contiguous() for k, v in tensors.items()}, args.out, metadata=meta)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
