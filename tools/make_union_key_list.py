#!/usr/bin/env python3
"""The tensor names and shapes of xinsir/controlnet-union-sdxl-1.0's published files (base: 6 control types;
ProMax: 8), for networks/tests/networks/controlnet_union.rs, which checks that vkdiff's loader asks for
exactly these.

The real headers cannot be read here (no network), so the lists come from diffusers' ControlNetUnionModel at
xinsir's config (docs/notes/controlnet-union.md §1: the SDXL ControlNet config with
conditioning_embedding_out_channels [16, 32, 96, 256], num_control_type 6 or 8), built on the meta device (no
weights allocated). The script asserts that removing the 19 union tensors leaves exactly diffusers'
ControlNetModel at the same config, whose list is the one read from the diffusers/controlnet-*-sdxl-1.0 headers.

Writes tests/fixtures/controlnet_union/keys-6.tsv and keys-8.tsv: name<TAB>shape (comma-separated), sorted.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1.
  /tmp/ref/bin/python tools/make_union_key_list.py"""
import pathlib

import torch
from diffusers import ControlNetModel, ControlNetUnionModel

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "tests/fixtures/controlnet_union"
SDXL_CONTROLNET = dict(
    in_channels=4, conditioning_channels=3, block_out_channels=[320, 640, 1280],
    down_block_types=["DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"], layers_per_block=2,
    transformer_layers_per_block=[1, 2, 10], attention_head_dim=[5, 10, 20], cross_attention_dim=2048,
    use_linear_projection=True, norm_num_groups=32, norm_eps=1e-5, flip_sin_to_cos=True, freq_shift=0,
    addition_embed_type="text_time", addition_time_embed_dim=256, projection_class_embeddings_input_dim=2816,
    conditioning_embedding_out_channels=[16, 32, 96, 256], controlnet_conditioning_channel_order="rgb",
    global_pool_conditions=False, act_fn="silu")
UNION = ("task_embedding", "transformer_layes.", "spatial_ch_projs.", "control_add_embedding.")


def shapes(model):
    return {k: tuple(v.shape) for k, v in model.state_dict().items()}


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    with torch.device("meta"):
        plain = shapes(ControlNetModel(**SDXL_CONTROLNET, mid_block_type="UNetMidBlock2DCrossAttn"))
        for types in (6, 8):
            union = shapes(ControlNetUnionModel(**SDXL_CONTROLNET, num_control_type=types))
            extra = sorted(k for k in union if k.startswith(UNION))
            assert len(extra) == 19, extra
            rest = {k: v for k, v in union.items() if not k.startswith(UNION)}
            assert rest == plain, sorted(set(rest.items()) ^ set(plain.items()))
            assert union["task_embedding"] == (types, 320)
            assert union["control_add_embedding.linear_1.weight"] == (1280, 256 * types)
            lines = [f"{k}\t{','.join(map(str, union[k]))}\n" for k in sorted(union)]
            (OUT / f"keys-{types}.tsv").write_text("".join(lines))
            print(f"keys-{types}.tsv: {len(union)} tensors ({len(plain)} plain + {len(extra)} union), "
                  f"{sum(torch.Size(s).numel() for s in union.values())} parameters")


main()
