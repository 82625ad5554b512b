#!/usr/bin/env python3
"""ControlNet, IP-Adapter and LoRA fixtures for the tiny SDXL of tests/fixtures/pipeline/tiny-sdxl, and
diffusers' outputs for them (the paper's workflow: depth ControlNet + IP-Adapter + LoRAs), for vkdiff's
end-to-end tests.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), torchvision 0.29.2,
diffusers 0.42.1, transformers 5.23.0, peft 0.21.2, safetensors 0.8.0, pillow 13.0.0.
Setup and rerun (the tiny pipeline must exist; it is loaded, not regenerated):
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch torchvision diffusers transformers peft \
      safetensors open_clip_torch pillow
  /tmp/ref/bin/python tools/make_workflow_fixtures.py [--out tests/fixtures/workflow]
      [--pipeline tests/fixtures/pipeline/tiny-sdxl]

Writes under --out (all weights float16 on disk, with values float16 represents exactly, so the float32
reference runs use exactly the stored values; all randomness through explicit torch.Generator objects):
  controlnet/: diffusers ControlNetModel (config.json + diffusion_pytorch_model.fp16.safetensors only; load
      with variant="fp16"), the tiny UNet's encoder half (ControlNetModel.from_unet) with
      conditioning_embedding_out_channels [16, 16, 32, 32] (hint encoder: conv_in, 6 blocks with stride 2 at
      blocks 1, 3, 5, conv_out: 64x64 -> 8x8), every parameter redrawn non-zero; the zero convs and the hint
      conv_out are scaled by powers of two so that the residuals are about 0.3x the UNet's skips.
  controlnet-small/: the same with transformer_layers_per_block [0, 0, 0] (as diffusers/controlnet-depth-
      sdxl-1.0-small: each Transformer2DModel keeps norm/proj_in/proj_out but has no transformer blocks).
  controlnet-cldm.safetensors: controlnet/'s weights in the original "cldm" single-file layout with the
      `control_model.` prefix (time_embed, label_emb, input_blocks, middle_block as in the UNet single file;
      input_hint_block.{0,2,...,14}; zero_convs.{k}.0; middle_block_out.0), checked against diffusers'
      convert_controlnet_checkpoint (see records.json "checks" for what diffusers does with it).
  image_encoder/: transformers CLIPVisionModelWithProjection (config.json + model.safetensors), image_size 56,
      patch 14 (16 patches + class token), hidden 128 (2 heads of 64), 3 layers, MLP 512, gelu, projection 48.
      No preprocessor_config.json, as h94's folders: diffusers' load_ip_adapter then builds
      CLIPImageProcessor(size=image_size, crop_size=image_size).
  ip-adapter_tiny.safetensors: h94-style plain adapter (ImageProjModel 48 -> 4 tokens x 192) and
      ip_adapter.{1,3,...,13}.to_k_ip/to_v_ip.weight [64, 192].
  ip-adapter-plus_tiny.safetensors: h94-style plus adapter (Resampler over hidden_states[-2]: dim 128,
      2 heads of 64, depth 4 (diffusers only builds depth 4), 8 queries, ff x4, output 192) + the same
      per-layer keys.
  lora-kohya-ldm.safetensors, lora-kohya-diffusers.safetensors, lora-peft.safetensors: see LORAS below and
      records.json "loras" (every key is checked to be applied by diffusers, with the right scale).
  control.png (80x72 grey depth-like, near = bright), style-1.png (90x60), style-2.png (50x70): RGB 8-bit.
  records.safetensors + records.json: float32 reference tensors and every case's settings.
"""
import argparse
import copy
import json
import math
import pathlib
import shutil
import sys

import numpy as np
import torch
from PIL import Image

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import clip_vocab  # noqa: E402
from make_unet_fixtures import redraw, reference_ldm_names, representable_everywhere  # noqa: E402

import diffusers  # noqa: E402
import peft  # noqa: E402
import safetensors  # noqa: E402
import torchvision  # noqa: E402
import transformers  # noqa: E402
from diffusers import (  # noqa: E402
    ControlNetModel, DPMSolverMultistepScheduler, EulerAncestralDiscreteScheduler, EulerDiscreteScheduler,
    StableDiffusionXLControlNetPipeline, StableDiffusionXLPipeline,
)
from diffusers.loaders.single_file_utils import convert_controlnet_checkpoint  # noqa: E402
from diffusers.models.attention_processor import AttnProcessor2_0  # noqa: E402
from safetensors.torch import load_file, save_file  # noqa: E402
from transformers import CLIPVisionConfig, CLIPVisionModelWithProjection  # noqa: E402

CONTEXT = 192  # tiny UNet cross_attention_dim
HINT_CHANNELS = [16, 16, 32, 32]

IMAGE_ENCODER_CONFIG = dict(
    image_size=56, patch_size=14, num_channels=3, hidden_size=128, num_attention_heads=2, num_hidden_layers=3,
    intermediate_size=512, projection_dim=48, hidden_act="gelu", layer_norm_eps=1e-5, attention_dropout=0.0,
    dropout=0.0, initializer_factor=1.0, initializer_range=0.02,
)
PLUS = dict(dim=128, heads=2, depth=4, queries=8, ff_mult=4)

SAMPLERS = dict(euler=EulerDiscreteScheduler, euler_a=EulerAncestralDiscreteScheduler,
                dpmpp_2m=DPMSolverMultistepScheduler)

# LoRA modules: (name in the file, component, module path in the diffusers/transformers model, rank, alpha).
# Module paths of text encoders are given under `text_model.` (the names the stored tiny-sdxl files use;
# transformers 5's CLIPTextModel has no `text_model` submodule, CLIPTextModelWithProjection has).
T = "text_model.encoder.layers"
D1 = "down_blocks.1.attentions.0.transformer_blocks.0"
KOHYA_LDM = [
    # down_blocks.1.attentions.0 = input_blocks.3.1 (layers_per_block 1: input block 3i+... = 2i+j+1)
    *[(f"lora_unet_input_blocks_3_1_transformer_blocks_0_attn1_{a}", "unet", f"{D1}.attn1.{b}", 4, al)
      for (a, b, al) in (("to_q", "to_q", 2.0), ("to_k", "to_k", 2.0), ("to_v", "to_v", 2.0), ("to_out_0", "to_out.0", 2.0))],
    *[(f"lora_unet_input_blocks_3_1_transformer_blocks_0_attn2_{a}", "unet", f"{D1}.attn2.{a}", 4, 2.0)
      for a in ("to_q", "to_k", "to_v")],
    ("lora_unet_input_blocks_3_1_transformer_blocks_0_ff_net_0_proj", "unet", f"{D1}.ff.net.0.proj", 4, 3.0),
    ("lora_unet_input_blocks_3_1_transformer_blocks_0_ff_net_2", "unet", f"{D1}.ff.net.2", 4, 2.0),
    ("lora_unet_input_blocks_3_1_proj_in", "unet", "down_blocks.1.attentions.0.proj_in", 4, 2.0),
    ("lora_unet_input_blocks_3_1_proj_out", "unet", "down_blocks.1.attentions.0.proj_out", 4, 1.0),
    ("lora_unet_middle_block_1_transformer_blocks_0_attn1_to_k", "unet",
     "mid_block.attentions.0.transformer_blocks.0.attn1.to_k", 4, 2.0),
    ("lora_unet_output_blocks_2_1_transformer_blocks_0_attn2_to_out_0", "unet",
     "up_blocks.1.attentions.0.transformer_blocks.0.attn2.to_out.0", 4, 2.0),
    ("lora_unet_input_blocks_3_0_in_layers_2", "unet", "down_blocks.1.resnets.0.conv1", 4, 1.0),
    ("lora_unet_input_blocks_3_0_out_layers_3", "unet", "down_blocks.1.resnets.0.conv2", 4, 2.0),
    ("lora_unet_input_blocks_3_0_skip_connection", "unet", "down_blocks.1.resnets.0.conv_shortcut", 4, 4.0),
    ("lora_unet_input_blocks_3_0_emb_layers_1", "unet", "down_blocks.1.resnets.0.time_emb_proj", 4, 8.0),
    ("lora_unet_middle_block_2_in_layers_2", "unet", "mid_block.resnets.1.conv1", 4, 2.0),
    ("lora_unet_output_blocks_0_0_skip_connection", "unet", "up_blocks.0.resnets.0.conv_shortcut", 4, 2.0),
    ("lora_unet_output_blocks_5_0_out_layers_3", "unet", "up_blocks.2.resnets.1.conv2", 4, 2.0),
    ("lora_unet_input_blocks_2_0_op", "unet", "down_blocks.0.downsamplers.0.conv", 4, 3.0),
    ("lora_unet_output_blocks_1_2_conv", "unet", "up_blocks.0.upsamplers.0.conv", 4, 1.0),
    *[(f"lora_te1_text_model_encoder_layers_0_self_attn_{p}", "text_encoder", f"{T}.0.self_attn.{p}", 4, al)
      for p, al in (("q_proj", 2.0), ("k_proj", 2.0), ("v_proj", 2.0), ("out_proj", 2.0))],
    ("lora_te1_text_model_encoder_layers_2_mlp_fc1", "text_encoder", f"{T}.2.mlp.fc1", 4, 2.0),
    ("lora_te1_text_model_encoder_layers_2_mlp_fc2", "text_encoder", f"{T}.2.mlp.fc2", 4, 2.0),
    *[(f"lora_te2_text_model_encoder_layers_1_self_attn_{p}", "text_encoder_2", f"{T}.1.self_attn.{p}", 4, 2.0)
      for p in ("q_proj", "k_proj", "v_proj", "out_proj")],
    ("lora_te2_text_model_encoder_layers_1_mlp_fc1", "text_encoder_2", f"{T}.1.mlp.fc1", 4, 8.0),
    ("lora_te2_text_model_encoder_layers_1_mlp_fc2", "text_encoder_2", f"{T}.1.mlp.fc2", 4, 2.0),
]
D2 = "down_blocks.2.attentions.0.transformer_blocks.0"
KOHYA_DIFFUSERS = [
    *[(f"lora_unet_{D2.replace('.', '_')}_attn1_{a}", "unet", f"{D2}.attn1.{b}", 4, 1.0)
      for (a, b) in (("to_q", "to_q"), ("to_k", "to_k"), ("to_v", "to_v"), ("to_out_0", "to_out.0"))],
    (f"lora_unet_{D2.replace('.', '_')}_attn2_to_v", "unet", f"{D2}.attn2.to_v", 4, 1.0),
    (f"lora_unet_{D2.replace('.', '_')}_ff_net_0_proj", "unet", f"{D2}.ff.net.0.proj", 4, 1.0),
    ("lora_unet_mid_block_attentions_0_proj_out", "unet", "mid_block.attentions.0.proj_out", 4, 1.0),
    ("lora_unet_up_blocks_0_resnets_0_conv1", "unet", "up_blocks.0.resnets.0.conv1", 4, 2.0),
    ("lora_unet_up_blocks_0_resnets_0_conv_shortcut", "unet", "up_blocks.0.resnets.0.conv_shortcut", 4, 1.0),
    ("lora_unet_up_blocks_1_resnets_1_time_emb_proj", "unet", "up_blocks.1.resnets.1.time_emb_proj", 4, 8.0),
    ("lora_unet_down_blocks_1_downsamplers_0_conv", "unet", "down_blocks.1.downsamplers.0.conv", 4, 1.0),
    ("lora_unet_up_blocks_1_upsamplers_0_conv", "unet", "up_blocks.1.upsamplers.0.conv", 4, 1.0),
    ("lora_unet_mid_block_resnets_0_conv2", "unet", "mid_block.resnets.0.conv2", 4, 1.0),
]
# PEFT: one r / lora_alpha per component (written to the lora_adapter_metadata header as diffusers does).
PEFT_CONFIG = dict(unet=(4, 6.0), text_encoder=(4, 2.0), text_encoder_2=(2, 3.0))
PEFT_MODULES = [
    *[("unet", f"{D2}.{m}") for m in ("attn1.to_k", "attn1.to_out.0", "attn2.to_q", "ff.net.2")],
    ("unet", "down_blocks.2.attentions.0.proj_in"),
    ("unet", "up_blocks.1.attentions.1.transformer_blocks.0.attn2.to_v"),
    ("unet", "up_blocks.1.resnets.1.conv1"),
    ("unet", "up_blocks.1.resnets.0.conv_shortcut"),
    ("unet", "down_blocks.2.resnets.0.time_emb_proj"),
    *[("text_encoder", f"{T}.1.self_attn.{p}") for p in ("q_proj", "k_proj", "v_proj", "out_proj")],
    ("text_encoder", f"{T}.1.mlp.fc1"),
    *[("text_encoder_2", f"{T}.0.{p}") for p in ("self_attn.q_proj", "self_attn.k_proj", "mlp.fc2")],
]
# Parameters whose merged value is recorded (strength FUSE_STRENGTH), per LoRA file.
FUSE_STRENGTH = 0.7
FUSE_RECORDS = {
    "lora-kohya-ldm": [("unet", f"{D1}.attn1.to_k"), ("unet", "down_blocks.1.resnets.0.conv1"),
                       ("unet", "down_blocks.1.resnets.0.conv_shortcut"), ("text_encoder", f"{T}.0.self_attn.q_proj"),
                       ("text_encoder_2", f"{T}.1.self_attn.q_proj")],
    "lora-kohya-diffusers": [("unet", f"{D2}.attn1.to_k"), ("unet", "up_blocks.0.resnets.0.conv1"),
                             ("unet", "up_blocks.1.resnets.1.time_emb_proj")],
    "lora-peft": [("unet", f"{D2}.attn1.to_k"), ("unet", "up_blocks.1.resnets.1.conv1"),
                  ("text_encoder", f"{T}.1.self_attn.q_proj"), ("text_encoder_2", f"{T}.0.self_attn.q_proj")],
}

# Pipeline cases. Common: guidance 5.0, negative absent unless given.
CASES = [
    dict(name="base_check", prompt="a photo of a cat", seed=0, steps=4, sampler="euler", width=64, height=64),
    dict(name="cn", prompt="a stone bridge over a river, morning fog", seed=11, steps=4, sampler="euler",
         width=64, height=64, control=dict(model="controlnet", image="control.png", scale=0.7, start=0.0, end=1.0)),
    dict(name="cn_gated", prompt="a glass sculpture of a horse, museum lighting", seed=12, steps=4,
         sampler="euler_a", width=96, height=64,
         control=dict(model="controlnet", image="control.png", scale=1.0, start=0.25, end=0.75)),
    dict(name="cn_small", prompt="a desert canyon at sunset", seed=13, steps=4, sampler="euler", width=64,
         height=64, control=dict(model="controlnet-small", image="control.png", scale=1.0, start=0.0, end=1.0)),
    dict(name="ip_plain_two", prompt="a cosy reading nook with plants", seed=14, steps=4, sampler="euler",
         width=64, height=64,
         ip=dict(adapter="ip-adapter_tiny.safetensors", images=["style-1.png", "style-2.png"], scale=0.6)),
    dict(name="ip_plus", prompt="portrait of an old sailor", seed=15, steps=4, sampler="euler", width=64,
         height=64, ip=dict(adapter="ip-adapter-plus_tiny.safetensors", images=["style-1.png"], scale=0.8)),
    dict(name="lora_kohya_ldm", prompt="a red fox in tall grass", seed=16, steps=4, sampler="euler", width=64,
         height=64, loras=[("lora-kohya-ldm.safetensors", 0.8)]),
    dict(name="lora_kohya_diffusers", prompt="an isometric city block, pastel colours", seed=17, steps=4,
         sampler="euler", width=64, height=64, loras=[("lora-kohya-diffusers.safetensors", 0.8)]),
    dict(name="lora_peft", prompt="a bowl of cherries on a wooden table", seed=18, steps=4, sampler="euler",
         width=64, height=64, loras=[("lora-peft.safetensors", 0.8)]),
    dict(name="lora_two", prompt="a snowy mountain village at night", seed=19, steps=4, sampler="euler",
         width=64, height=64, loras=[("lora-kohya-ldm.safetensors", 0.8), ("lora-peft.safetensors", 0.5)]),
    dict(name="full", prompt="a cathedral interior with stained glass, volumetric light",
         negative_prompt="blurry, low quality", seed=20, steps=5, sampler="dpmpp_2m", width=64, height=64,
         control=dict(model="controlnet", image="control.png", scale=0.7, start=0.0, end=1.0),
         ip=dict(adapter="ip-adapter_tiny.safetensors", images=["style-1.png", "style-2.png"], scale=0.6),
         loras=[("lora-kohya-ldm.safetensors", 0.8), ("lora-peft.safetensors", 0.5)]),
]
GUIDANCE = 5.0

R = representable_everywhere


def gen_for(name):
    return torch.Generator().manual_seed(sum(map(ord, name)))


def pow2(x):
    return 2.0 ** round(math.log2(x))


# ---------------------------------------------------------------------------------------------
# Base pipeline


def load_base(folder):
    tok1 = clip_vocab.hf_tokenizer(folder / "tokenizer")
    tok2 = clip_vocab.hf_tokenizer(folder / "tokenizer_2")
    pipe = StableDiffusionXLPipeline.from_pretrained(
        folder, torch_dtype=torch.float32, tokenizer=tok1, tokenizer_2=tok2, add_watermarker=False)
    pipe.unet.set_attn_processor(AttnProcessor2_0())
    pipe.set_progress_bar_config(disable=True)
    return pipe


# ---------------------------------------------------------------------------------------------
# Images


def make_images(out):
    # Depth-like: a bright sphere (near) in front of a tilted floor fading into the distance; 8-bit grey.
    h, w = 72, 80
    y, x = torch.meshgrid(torch.arange(h, dtype=torch.float64) + 0.5, torch.arange(w, dtype=torch.float64) + 0.5,
                          indexing="ij")
    floor = 0.15 + 0.55 * (y / h) ** 1.5 + 0.05 * (x / w)
    r2 = ((x - 30) / 20) ** 2 + ((y - 34) / 20) ** 2
    sphere = torch.where(r2 < 1, 0.55 + 0.4 * torch.sqrt((1 - r2).clamp(min=0)), torch.zeros_like(r2))
    box = ((x > 52) & (x < 74) & (y > 12) & (y < 50)).double() * (0.45 + 0.1 * (y - 12) / 38)
    depth = torch.maximum(torch.maximum(floor, sphere), box)
    grey = (depth.clamp(0, 1) * 255).round().to(torch.uint8)
    Image.fromarray(grey[..., None].expand(h, w, 3).numpy().copy(), "RGB").save(out / "control.png")

    def colourful(w, h, phase):
        y, x = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64),
                              indexing="ij")
        r = 0.5 + 0.5 * torch.sin(x / w * 5.0 + phase) * torch.cos(y / h * 3.0)
        g = 0.5 + 0.5 * torch.sin((x + y) / (w + h) * 9.0 + 2 * phase)
        b = ((x - w / 3) ** 2 + (y - h / 2) ** 2).sqrt() / max(w, h)
        b = 0.5 + 0.5 * torch.cos(b * 14.0 - phase)
        stripes = ((x.long() // 7 + y.long() // 5) % 2 == 0).double()
        img = torch.stack([r, g * (0.7 + 0.3 * stripes), b], -1)
        return (img.clamp(0, 1) * 255).round().to(torch.uint8).numpy()

    Image.fromarray(colourful(90, 60, 0.3), "RGB").save(out / "style-1.png")
    Image.fromarray(colourful(50, 70, 2.1), "RGB").save(out / "style-2.png")


def open_rgb(path):
    return Image.open(path).convert("RGB")


# ---------------------------------------------------------------------------------------------
# ControlNet


def unet_skip_stds(unet, inputs):
    """Standard deviations of the UNet's skip tensors (the ControlNet residual targets) and mid output."""
    found = []
    hooks = [unet.conv_in.register_forward_hook(lambda m, i, o: found.append(o))]
    for b in unet.down_blocks:
        hooks.append(b.register_forward_hook(lambda m, i, o: found.extend(o[1])))
    mid = []
    hooks.append(unet.mid_block.register_forward_hook(lambda m, i, o: mid.append(o)))
    unet(inputs["sample"], inputs["timestep"], encoder_hidden_states=inputs["encoder_hidden_states"],
         added_cond_kwargs=dict(text_embeds=inputs["text_embeds"], time_ids=inputs["time_ids"]))
    for h in hooks:
        h.remove()
    return [t.std().item() for t in found], mid[0].std().item()


def controlnet_forward(cn, inputs, scale=1.0):
    down, mid = cn(inputs["sample"], inputs["timestep"], encoder_hidden_states=inputs["encoder_hidden_states"],
                   controlnet_cond=inputs["controlnet_cond"], conditioning_scale=scale,
                   added_cond_kwargs=dict(text_embeds=inputs["text_embeds"], time_ids=inputs["time_ids"]),
                   return_dict=False)
    return list(down), mid


def build_controlnet(unet, small, inputs):
    name = "controlnet-small" if small else "controlnet"
    gen = gen_for(name)
    if small:
        config = {k: v for k, v in ControlNetModel.from_unet(unet, conditioning_embedding_out_channels=HINT_CHANNELS)
                  .config.items() if not k.startswith("_")}
        config["transformer_layers_per_block"] = [0, 0, 0]
        cn = ControlNetModel(**config)
    else:
        cn = ControlNetModel.from_unet(unet, conditioning_embedding_out_channels=HINT_CHANNELS)
    cn.eval()
    cn.set_attn_processor(AttnProcessor2_0())
    redraw(cn, gen)
    # Scale the hint output and the zero convs (powers of two keep the values representable) so the
    # residuals are about 0.3x the UNet's skips.
    with torch.no_grad():
        cn.controlnet_cond_embedding.conv_out.weight.mul_(0.5)
        skips, mid_std = unet_skip_stds(unet, inputs)
        down, mid = controlnet_forward(cn, inputs)
        for k, (d, s) in enumerate(zip(down, skips)):
            f = pow2(0.3 * s / d.std().item())
            cn.controlnet_down_blocks[k].weight.mul_(f)
            cn.controlnet_down_blocks[k].bias.mul_(f)
        f = pow2(0.3 * mid_std / mid.std().item())
        cn.controlnet_mid_block.weight.mul_(f)
        cn.controlnet_mid_block.bias.mul_(f)
        for p in cn.parameters():
            p.copy_(R(p))  # scaling down may have made a few values float16 subnormals: those become 0
            assert (p != 0).float().mean() > 0.99
        down, mid = controlnet_forward(cn, inputs)
    ratios = [round(d.std().item() / s, 3) for d, s in zip(down, skips)] + [round(mid.std().item() / mid_std, 3)]
    print(f"{name}: parameters {sum(p.numel() for p in cn.parameters())}, residual/skip std ratios {ratios}")
    return cn, ratios


def save_controlnet(cn, folder):
    if folder.exists():
        shutil.rmtree(folder)
    copy.deepcopy(cn).to(torch.float16).save_pretrained(folder, variant="fp16", safe_serialization=True)
    files = sorted(p.name for p in folder.iterdir())
    assert files == ["config.json", "diffusion_pytorch_model.fp16.safetensors"], files
    back = ControlNetModel.from_pretrained(folder, variant="fp16", torch_dtype=torch.float32)
    a, b = cn.state_dict(), back.state_dict()
    assert set(a) == set(b) and all(torch.equal(a[k], b[k]) for k in a), "controlnet reload differs"


def cldm_names(cn, unet_config):
    """diffusers ControlNetModel name -> original cldm name (without the control_model. prefix)."""
    to_ldm = {d: l for l, d in reference_ldm_names(unet_config).items()}
    n_blocks = len(cn.controlnet_cond_embedding.blocks)
    out = {}
    for k in cn.state_dict():
        if k in to_ldm:
            out[k] = to_ldm[k]
            continue
        parts = k.split(".")
        if k.startswith("controlnet_cond_embedding.conv_in."):
            out[k] = f"input_hint_block.0.{parts[-1]}"
        elif k.startswith("controlnet_cond_embedding.blocks."):
            out[k] = f"input_hint_block.{2 * int(parts[2]) + 2}.{parts[-1]}"
        elif k.startswith("controlnet_cond_embedding.conv_out."):
            out[k] = f"input_hint_block.{2 * n_blocks + 2}.{parts[-1]}"
        elif k.startswith("controlnet_down_blocks."):
            out[k] = f"zero_convs.{parts[1]}.0.{parts[-1]}"
        elif k.startswith("controlnet_mid_block."):
            out[k] = f"middle_block_out.0.{parts[-1]}"
        else:
            raise SystemExit(f"no cldm name for {k}")
    assert len(set(out.values())) == len(out)
    return out


def save_cldm(cn, unet_config, path, checks):
    names = cldm_names(cn, unet_config)
    state = cn.state_dict()
    ldm = {"control_model." + names[k]: v.to(torch.float16).contiguous() for k, v in state.items()}
    save_file(ldm, path)
    loaded = {k: v.float() for k, v in load_file(path).items()}
    converted = convert_controlnet_checkpoint(loaded, dict(cn.config))
    converted = {k: v for k, v in converted.items() if v is not None}
    missing = sorted(set(state) - set(converted))
    extra = sorted(set(converted) - set(state))
    wrong = sorted(k for k in set(state) & set(converted) if not torch.equal(state[k], converted[k]))
    checks["cldm_convert_controlnet_checkpoint"] = dict(
        tensors=len(ldm), converted=len(converted), missing_after_conversion=missing, unexpected=extra,
        differing=wrong)
    print(f"cldm: {len(ldm)} tensors; diffusers' convert_controlnet_checkpoint gives {len(converted)}, missing "
          f"{missing}, unexpected {extra}, differing {wrong}")
    assert not extra and not wrong
    # Missing keys must be exactly the ones diffusers' converter has no rule for (label_emb -> add_embedding);
    # every other name round-trips.
    assert all(k.startswith("add_embedding.") for k in missing), missing
    try:
        single = ControlNetModel.from_single_file(str(path), config=str(path.parent / "controlnet"),
                                                  torch_dtype=torch.float32, local_files_only=True)
        sd = single.state_dict()
        bad = sorted(k for k in state if k not in sd or not torch.equal(sd[k], state[k]))
        checks["cldm_from_single_file"] = dict(ok=not bad, differing=bad)
        print(f"cldm: ControlNetModel.from_single_file -> {'identical' if not bad else f'differs in {bad}'}")
    except Exception as e:  # report, do not fail: the names are checked above
        checks["cldm_from_single_file"] = dict(ok=False, error=f"{type(e).__name__}: {e}"[:500])
        print(f"cldm: ControlNetModel.from_single_file failed: {type(e).__name__}: {str(e)[:300]}")


# ---------------------------------------------------------------------------------------------
# IP-Adapter


def build_image_encoder(folder):
    model = CLIPVisionModelWithProjection(CLIPVisionConfig(**IMAGE_ENCODER_CONFIG)).eval()
    redraw(model, gen_for("image_encoder"))
    if folder.exists():
        shutil.rmtree(folder)
    copy.deepcopy(model).to(torch.float16).save_pretrained(folder, safe_serialization=True)
    files = sorted(p.name for p in folder.iterdir())
    assert files == ["config.json", "model.safetensors"], files
    keys = set(load_file(folder / "model.safetensors"))
    assert "visual_projection.weight" in keys and "vision_model.embeddings.class_embedding" in keys, sorted(keys)[:5]
    back = CLIPVisionModelWithProjection.from_pretrained(folder, dtype=torch.float32)
    a, b = model.state_dict(), back.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    return model


def ip_layer_keys(unet):
    """(N, hidden) for every attn2 processor, N = position in unet.attn_processors (sdxl.md §7.4)."""
    out = []
    for i, name in enumerate(unet.attn_processors.keys()):
        if name.endswith("attn2.processor"):
            out.append((i, unet.get_submodule(name[: -len(".processor")]).to_q.out_features, name))
    return out


def ip_layers(unet, gen):
    state = {}
    for n, hidden, _ in ip_layer_keys(unet):
        for w in ("to_k_ip", "to_v_ip"):
            state[f"ip_adapter.{n}.{w}.weight"] = R(torch.randn(hidden, CONTEXT, generator=gen) / CONTEXT ** 0.5)
    return state


def vec(shape, gen, base=0.0, scale=0.1):
    return R(base + scale * torch.randn(shape, generator=gen))


def mat(shape, gen):
    return R(torch.randn(shape, generator=gen) / math.prod(shape[1:]) ** 0.5)


def build_plain_adapter(unet, emb_dim):
    gen = gen_for("ip-adapter_tiny")
    state = {
        "image_proj.proj.weight": mat((4 * CONTEXT, emb_dim), gen),
        "image_proj.proj.bias": vec((4 * CONTEXT,), gen, 0.0, 0.5),
        "image_proj.norm.weight": vec((CONTEXT,), gen, 1.0),
        "image_proj.norm.bias": vec((CONTEXT,), gen),
    }
    return state | ip_layers(unet, gen)


def build_plus_adapter(unet, emb_dim):
    gen = gen_for("ip-adapter-plus_tiny")
    d, inner = PLUS["dim"], PLUS["heads"] * 64
    p = "image_proj."
    state = {
        p + "latents": R(torch.randn(1, PLUS["queries"], d, generator=gen) / d ** 0.5),
        p + "proj_in.weight": mat((d, emb_dim), gen), p + "proj_in.bias": vec((d,), gen),
    }
    for L in range(PLUS["depth"]):
        q = f"{p}layers.{L}."
        state |= {
            q + "0.norm1.weight": vec((d,), gen, 1.0), q + "0.norm1.bias": vec((d,), gen),
            q + "0.norm2.weight": vec((d,), gen, 1.0), q + "0.norm2.bias": vec((d,), gen),
            q + "0.to_q.weight": mat((inner, d), gen), q + "0.to_kv.weight": mat((2 * inner, d), gen),
            q + "0.to_out.weight": mat((d, inner), gen),
            q + "1.0.weight": vec((d,), gen, 1.0), q + "1.0.bias": vec((d,), gen),
            q + "1.1.weight": mat((PLUS["ff_mult"] * d, d), gen), q + "1.3.weight": mat((d, PLUS["ff_mult"] * d), gen),
        }
    state |= {p + "proj_out.weight": mat((CONTEXT, d), gen), p + "proj_out.bias": vec((CONTEXT,), gen),
              p + "norm_out.weight": vec((CONTEXT,), gen, 1.0), p + "norm_out.bias": vec((CONTEXT,), gen)}
    return state | ip_layers(unet, gen)


def reference_plain_proj(state, embeds):
    """h94 ImageProjModel, written from the file: LayerNorm(reshape(proj(x), (N, 4, C)))."""
    x = embeds @ state["image_proj.proj.weight"].T + state["image_proj.proj.bias"]
    x = x.reshape(embeds.shape[0], 4, CONTEXT)
    return torch.nn.functional.layer_norm(x, (CONTEXT,), state["image_proj.norm.weight"], state["image_proj.norm.bias"])


def reference_resampler(state, x):
    """h94 Resampler (ip_adapter/resampler.py), written from the file."""
    p = "image_proj."
    ln = torch.nn.functional.layer_norm
    d, heads = PLUS["dim"], PLUS["heads"]
    lat = state[p + "latents"].repeat(x.shape[0], 1, 1)
    x = x @ state[p + "proj_in.weight"].T + state[p + "proj_in.bias"]
    for L in range(PLUS["depth"]):
        q = f"{p}layers.{L}."
        xn = ln(x, (d,), state[q + "0.norm1.weight"], state[q + "0.norm1.bias"])
        ln_ = ln(lat, (d,), state[q + "0.norm2.weight"], state[q + "0.norm2.bias"])
        kv_in = torch.cat([xn, ln_], 1)
        qq = ln_ @ state[q + "0.to_q.weight"].T
        k, v = (kv_in @ state[q + "0.to_kv.weight"].T).chunk(2, -1)

        def split(t):
            return t.reshape(t.shape[0], t.shape[1], heads, 64).transpose(1, 2)
        scale = 1 / math.sqrt(math.sqrt(64))
        w = torch.softmax((split(qq) * scale) @ (split(k) * scale).transpose(-1, -2), -1)
        o = (w @ split(v)).transpose(1, 2).reshape(lat.shape[0], lat.shape[1], heads * 64)
        lat = o @ state[q + "0.to_out.weight"].T + lat
        h = ln(lat, (d,), state[q + "1.0.weight"], state[q + "1.0.bias"]) @ state[q + "1.1.weight"].T
        lat = torch.nn.functional.gelu(h) @ state[q + "1.3.weight"].T + lat
    lat = lat @ state[p + "proj_out.weight"].T + state[p + "proj_out.bias"]
    return ln(lat, (CONTEXT,), state[p + "norm_out.weight"], state[p + "norm_out.bias"])


def check_ip_loaded(pipe, state, out):
    """diffusers took every key of the file, and nothing else."""
    unet = pipe.unet
    procs = unet.attn_processors
    used = set()
    for n, hidden, name in ip_layer_keys(unet):
        proc = procs[name]
        assert type(proc).__name__.startswith("IPAdapterAttnProcessor"), (name, type(proc))
        for w in ("to_k_ip", "to_v_ip"):
            key = f"ip_adapter.{n}.{w}.weight"
            assert torch.equal(getattr(proc, w)[0].weight, state[key]), key
            used.add(key)
    ip_keys = {k for k in state if k.startswith("ip_adapter.")}
    assert ip_keys == used, ip_keys ^ used
    assert pipe.feature_extractor is not None and pipe.image_encoder is not None
    fe = pipe.feature_extractor
    return dict(feature_extractor_class=type(fe).__module__ + "." + type(fe).__name__,
                feature_extractor_mro=[c.__name__ for c in type(fe).__mro__[:3]],
                size=dict(fe.size), crop_size=dict(fe.crop_size), resample=int(fe.resample),
                image_mean=list(fe.image_mean), image_std=list(fe.image_std), rescale_factor=fe.rescale_factor,
                do_convert_rgb=fe.do_convert_rgb)


def load_ip(pipe, out, weight_name):
    pipe.load_ip_adapter(str(out), subfolder="", weight_name=weight_name, image_encoder_folder="image_encoder",
                         low_cpu_mem_usage=False)


# ---------------------------------------------------------------------------------------------
# LoRA


def module_weight(pipe, component, path):
    model = getattr(pipe, component)
    if component == "text_encoder" and not hasattr(model, "text_model"):
        path = path.removeprefix("text_model.")
    m = model.get_submodule(path)
    return m


def base_weight(pipe, component, path):
    m = module_weight(pipe, component, path)
    return (m.base_layer.weight if hasattr(m, "base_layer") else m.weight).detach().clone()


def lora_pair(gen, weight, r, scale):
    """down [r, in(, kh, kw)], up [out, r(, 1, 1)] with delta = scale·up·down about 0.4x the weight's size."""
    out_f, in_f = weight.shape[:2]
    kernel = tuple(weight.shape[2:])
    fan_in = in_f * math.prod(kernel)
    down = R(torch.randn((r, in_f) + kernel, generator=gen) / fan_in ** 0.5)
    up = R(torch.randn((out_f, r) + (1,) * len(kernel), generator=gen) * (0.4 / scale) / r ** 0.5)
    return down, up


def delta(down, up, shape):
    return (up.flatten(1) @ down.flatten(1)).reshape(shape)


def build_kohya(pipe, modules, stem):
    gen = gen_for(stem)
    state, spec = {}, []
    for name, comp, path, r, alpha in modules:
        w = base_weight(pipe, comp, path)
        down, up = lora_pair(gen, w, r, alpha / r)
        state[f"{name}.lora_down.weight"] = down
        state[f"{name}.lora_up.weight"] = up
        state[f"{name}.alpha"] = torch.tensor(alpha)
        spec.append(dict(key=name, component=comp, module=path, rank=r, alpha=alpha, scale=alpha / r,
                         down=list(down.shape), up=list(up.shape)))
    return state, spec, None


def build_peft(pipe, stem):
    gen = gen_for(stem)
    state, spec, targets = {}, [], {}
    for comp, path in PEFT_MODULES:
        r, alpha = PEFT_CONFIG[comp]
        w = base_weight(pipe, comp, path)
        down, up = lora_pair(gen, w, r, alpha / r)
        state[f"{comp}.{path}.lora_A.weight"] = down
        state[f"{comp}.{path}.lora_B.weight"] = up
        spec.append(dict(key=f"{comp}.{path}", component=comp, module=path, rank=r, alpha=alpha, scale=alpha / r,
                         down=list(down.shape), up=list(up.shape)))
        # target names as suffixes that match with and without the text_model. level
        targets.setdefault(comp, []).append(path.removeprefix("text_model."))
    metadata = {}
    for comp, (r, alpha) in PEFT_CONFIG.items():
        config = peft.LoraConfig(r=r, lora_alpha=alpha, target_modules=sorted(targets[comp]),
                                 init_lora_weights=True).to_dict()
        config = {k: (sorted(v) if isinstance(v, set) else v) for k, v in config.items()}
        metadata |= {f"{comp}.{k}": v for k, v in config.items()}
    return state, spec, metadata


def save_lora(state, path, metadata):
    state = {k: v.to(torch.float16).contiguous() if v.ndim else v.to(torch.float16).reshape(()) for k, v in state.items()}
    header = {"format": "pt"}
    if metadata is not None:
        # exactly as diffusers' write_lora_layers writes it
        header["lora_adapter_metadata"] = json.dumps(metadata, indent=2, sort_keys=True)
    save_file(state, path, metadata=header)


def lora_modules(pipe):
    found = {}
    for comp in ("unet", "text_encoder", "text_encoder_2"):
        for name, m in getattr(pipe, comp).named_modules():
            if hasattr(m, "lora_A") and len(m.lora_A):
                if comp == "text_encoder" and not name.startswith("text_model."):
                    name = "text_model." + name
                found[(comp, name)] = m
    return found


def file_pair(f, key):
    if key.startswith("lora_"):  # kohya
        return f[key + ".lora_down.weight"], f[key + ".lora_up.weight"]
    return f[key + ".lora_A.weight"], f[key + ".lora_B.weight"]


def check_lora(pipe, path, spec, adapter):
    """Every module of the file is wrapped by PEFT with the file's down/up and scale alpha/r; no other."""
    pipe.load_lora_weights(str(path), adapter_name=adapter)
    found = {k: m for k, m in lora_modules(pipe).items() if adapter in m.lora_A}
    want = {(s["component"], s["module"]): s for s in spec}
    if set(found) != set(want):
        raise SystemExit(f"{path.name}: diffusers wrapped {sorted(set(found) - set(want))} and ignored "
                         f"{sorted(set(want) - set(found))}")
    f = load_file(path)
    bad = []
    for (comp, mod), s in want.items():
        m = found[(comp, mod)]
        down, up = file_pair(f, s["key"])
        a, b = m.lora_A[adapter].weight, m.lora_B[adapter].weight
        if not (torch.equal(a, down.float().reshape(a.shape)) and torch.equal(b, up.float().reshape(b.shape))):
            raise SystemExit(f"{path.name}: {comp}.{mod} holds other down/up weights than the file")
        if a.shape != down.shape or b.shape != up.shape:
            raise SystemExit(f"{path.name}: {comp}.{mod} shapes {a.shape}/{b.shape} vs {down.shape}/{up.shape}")
        if not math.isclose(m.scaling[adapter], s["scale"], rel_tol=1e-6):
            bad.append(f"{s['key']}: scaling {m.scaling[adapter]} != alpha/r {s['scale']}")
    if bad:
        raise SystemExit(f"{path.name}: diffusers applies other scales than the file's alpha/r:\n  " + "\n  ".join(bad))
    return len(found)


def lora_fuse_records(pipe, path, spec, adapter, tensors, stem):
    """fuse_lora at FUSE_STRENGTH: the merged weight of every module equals W + s·(alpha/r)·up·down; the
    listed parameters are recorded (merged and base)."""
    base = {(s["component"], s["module"]): base_weight(pipe, s["component"], s["module"]) for s in spec}
    f = load_file(path)
    components = sorted({s["component"] for s in spec})
    pipe.load_lora_weights(str(path), adapter_name=adapter)
    pipe.fuse_lora(components=components, lora_scale=FUSE_STRENGTH, adapter_names=[adapter])
    worst = 0.0
    records = []
    for s in spec:
        key = (s["component"], s["module"])
        down, up = file_pair(f, s["key"])
        w0 = base[key]
        expect = w0 + FUSE_STRENGTH * s["scale"] * delta(down.float(), up.float(), w0.shape)
        fused = base_weight(pipe, *key)
        err = (fused - expect).abs().max().item()
        worst = max(worst, err / expect.abs().max().item())
        if err > 1e-5 * expect.abs().max().item():
            raise SystemExit(f"{path.name}: fused {key} differs from W + s(alpha/r)BA by {err}")
        if key in FUSE_RECORDS[stem]:
            name = f"{s['component']}.{s['module']}.weight"
            tensors[f"lora.{stem}.{name}"] = fused.contiguous()
            tensors[f"base.{name}"] = w0.contiguous()
            records.append(dict(param=name, merged=f"lora.{stem}.{name}", base=f"base.{name}",
                                lora_key=s["key"], rank=s["rank"], alpha=s["alpha"],
                                delta_scale=FUSE_STRENGTH * s["scale"]))
    assert len(records) == len(FUSE_RECORDS[stem]), stem
    pipe.unfuse_lora(components=components)
    pipe.unload_lora_weights()
    return records, worst


# ---------------------------------------------------------------------------------------------
# Records


def check_sane(name, t):
    if not torch.isfinite(t).all():
        raise SystemExit(f"{name}: non-finite values")
    if t.numel() > 1 and t.std().item() < 1e-4:
        raise SystemExit(f"{name}: (nearly) constant, std {t.std().item()}")


def component_records(base_folder, out, unet_inputs, cns, ip_states, tensors, meta):
    pipe = cn_pipeline(base_folder, cns["controlnet"])
    control = open_rgb(out / "control.png")
    # (b) the control image as the pipeline prepares it (VaeImageProcessor, do_normalize False)
    for w, h in ((64, 64), (96, 64)):
        img = pipe.prepare_image(control, width=w, height=h, batch_size=1, num_images_per_prompt=1,
                                 device="cpu", dtype=torch.float32)
        tensors[f"control_image.{w}x{h}"] = img.contiguous()
    meta["control_image"] = dict(
        source="control.png (80x72)", tensors={f"{w}x{h}": f"control_image.{w}x{h}" for w, h in ((64, 64), (96, 64))},
        note="pipe.prepare_image(control.png, width, height, batch_size=1, num_images_per_prompt=1) of "
             "StableDiffusionXLControlNetPipeline: VaeImageProcessor(vae_scale_factor=8, do_convert_rgb=True, "
             "do_normalize=False).preprocess -> PIL resize to (width, height) with resample "
             f"'{pipe.control_image_processor.config.resample}' (no crop, aspect not kept), /255, NCHW in [0,1]")
    # (a) ControlNet forwards
    inputs = dict(unet_inputs, controlnet_cond=tensors["control_image.64x64"].repeat(2, 1, 1, 1))
    for k, v in inputs.items():
        tensors[f"cn.input.{k}"] = v.contiguous()
    meta["controlnet_forward"] = dict(
        inputs={k: f"cn.input.{k}" for k in inputs}, conditioning_scale=1.0, models={},
        note="down, mid = ControlNetModel(sample, timestep, encoder_hidden_states, controlnet_cond, "
             "conditioning_scale=1.0, added_cond_kwargs=dict(text_embeds, time_ids)); controlnet_cond = "
             "control_image.64x64 twice")
    for name, cn in cns.items():
        down, mid = controlnet_forward(cn, inputs)
        for k, d in enumerate(down):
            tensors[f"cn.{name}.down.{k}"] = d.contiguous()
        tensors[f"cn.{name}.mid"] = mid.contiguous()
        meta["controlnet_forward"]["models"][name] = dict(
            down=[f"cn.{name}.down.{k}" for k in range(len(down))], mid=f"cn.{name}.mid",
            shapes=[list(d.shape) for d in down] + [list(mid.shape)])
    del pipe

    # (c), (d) image encoder and projections, through the pipeline's own functions
    pipe = load_base(base_folder)
    load_ip(pipe, out, "ip-adapter_tiny.safetensors")
    fe_info = check_ip_loaded(pipe, ip_states["plain"], out)
    styles = {s: open_rgb(out / f"{s}.png") for s in ("style-1", "style-2")}
    enc = pipe.image_encoder
    clip = {}
    for s, img in styles.items():
        pv = pipe.feature_extractor(img, return_tensors="pt").pixel_values
        o = enc(pv, output_hidden_states=True)
        clip[s] = dict(pixel_values=pv, image_embeds=o.image_embeds, hidden_m2=o.hidden_states[-2])
    z = torch.zeros(1, 3, IMAGE_ENCODER_CONFIG["image_size"], IMAGE_ENCODER_CONFIG["image_size"])
    o = enc(z, output_hidden_states=True)
    clip["zeros"] = dict(pixel_values=z, image_embeds=o.image_embeds, hidden_m2=o.hidden_states[-2])
    both = pipe.feature_extractor([styles["style-1"], styles["style-2"]], return_tensors="pt").pixel_values
    assert torch.equal(both, torch.cat([clip["style-1"]["pixel_values"], clip["style-2"]["pixel_values"]]))
    for s, d in clip.items():
        for k, v in d.items():
            if not (s == "zeros" and k == "pixel_values"):
                tensors[f"clip.{s}.{k}"] = v.contiguous()
    # plain projection, as prepare_ip_adapter_image_embeds + encoder_hid_proj do it
    proj = pipe.unet.encoder_hid_proj
    plain = ip_states["plain"]
    embeds = pipe.prepare_ip_adapter_image_embeds([[styles["style-1"], styles["style-2"]]], None, "cpu", 1, True)
    assert len(embeds) == 1 and embeds[0].shape == (2, 2, IMAGE_ENCODER_CONFIG["projection_dim"]), embeds[0].shape
    assert torch.equal(embeds[0][0], torch.zeros_like(embeds[0][0]))
    # (the encoder runs on both images as one batch: equal to the single-image runs up to float rounding)
    assert torch.allclose(embeds[0][1], torch.cat([clip["style-1"]["image_embeds"], clip["style-2"]["image_embeds"]]),
                          atol=1e-5)
    tokens = proj(embeds)[0]  # [2 (uncond, cond), 2 images, 4, 192]
    ref = torch.stack([reference_plain_proj(plain, embeds[0][i]) for i in range(2)])
    assert torch.allclose(tokens, ref, atol=1e-5), (tokens - ref).abs().max()
    tensors["ip_plain.two.tokens"] = tokens[1:].contiguous()
    tensors["ip_plain.two.negative_tokens"] = tokens[:1].contiguous()
    for s in ("style-1", "style-2"):
        tensors[f"ip_plain.{s}.tokens"] = proj([clip[s]["image_embeds"][None]])[0][:, 0].contiguous()
    tensors["ip_plain.negative.tokens"] = proj([torch.zeros(1, 1, IMAGE_ENCODER_CONFIG["projection_dim"])])[0][:, 0]
    pipe.unload_ip_adapter()
    load_ip(pipe, out, "ip-adapter-plus_tiny.safetensors")
    check_ip_loaded(pipe, ip_states["plus"], out)
    proj = pipe.unet.encoder_hid_proj
    embeds = pipe.prepare_ip_adapter_image_embeds([styles["style-1"]], None, "cpu", 1, True)
    assert embeds[0].shape == (2, 1, 17, IMAGE_ENCODER_CONFIG["hidden_size"]), embeds[0].shape
    assert torch.equal(embeds[0][1], clip["style-1"]["hidden_m2"])
    assert torch.equal(embeds[0][0], clip["zeros"]["hidden_m2"])
    tokens = proj(embeds)[0]
    ref = torch.stack([reference_resampler(ip_states["plus"], embeds[0][i]) for i in range(2)])
    assert torch.allclose(tokens, ref, atol=1e-4), (tokens - ref).abs().max()
    for s in ("style-1", "style-2"):
        tensors[f"ip_plus.{s}.tokens"] = proj([clip[s]["hidden_m2"][None]])[0][:, 0].contiguous()
    tensors["ip_plus.negative.tokens"] = proj([clip["zeros"]["hidden_m2"][None]])[0][:, 0].contiguous()
    assert torch.allclose(tensors["ip_plus.style-1.tokens"], tokens[1], atol=1e-5)
    meta["image_encoder"] = dict(
        config=IMAGE_ENCODER_CONFIG, feature_extractor=fe_info,
        tensors={s: {k: f"clip.{s}.{k}" for k in d if not (s == "zeros" and k == "pixel_values")}
                 for s, d in clip.items()},
        note="pixel_values = pipe.feature_extractor(PIL image).pixel_values (the CLIPImageProcessor that "
             "load_ip_adapter builds); image_embeds = image_encoder(pixel_values).image_embeds; hidden_m2 = "
             "image_encoder(pixel_values, output_hidden_states=True).hidden_states[-2] (no post_layernorm); "
             "'zeros' = an all-zero pixel_values tensor [1,3,56,56] (the plus adapter's CFG negative).")
    meta["ip_projection"] = dict(
        plain={"style-1": "ip_plain.style-1.tokens", "style-2": "ip_plain.style-2.tokens",
               "negative": "ip_plain.negative.tokens", "two": "ip_plain.two.tokens",
               "two_negative": "ip_plain.two.negative_tokens"},
        plus={"style-1": "ip_plus.style-1.tokens", "style-2": "ip_plus.style-2.tokens",
              "negative": "ip_plus.negative.tokens"},
        note="tokens = unet.encoder_hid_proj([embeds[None]])[0][:, 0]: plain: [1,4,192] from image_embeds [1,48]; "
             "negative (CFG) = projection of zeros_like(image_embeds). plus: [1,8,192] from hidden_m2 [1,17,128]; "
             "negative = projection of hidden_m2 of zero pixels. 'two' = both style images given to one adapter "
             "(ip_adapter_image=[[style-1, style-2]]): [1, 2 images, 4, 192]; the attention processor flattens "
             "it to 8 tokens (style-1's 4 then style-2's 4) in one softmax.")


def cn_pipeline(base_folder, controlnet):
    base = load_base(base_folder)
    comps = {k: v for k, v in base.components.items()}
    pipe = StableDiffusionXLControlNetPipeline(**comps, controlnet=controlnet, force_zeros_for_empty_prompt=True,
                                               add_watermarker=False)
    pipe.set_progress_bar_config(disable=True)
    return pipe


def run_case(case, base_folder, out, cns):
    c = case
    if "control" in c:
        pipe = cn_pipeline(base_folder, cns[c["control"]["model"]])
    else:
        pipe = load_base(base_folder)
    pipe.scheduler = SAMPLERS[c["sampler"]].from_config(pipe.scheduler.config)
    kwargs = dict(prompt=c["prompt"], negative_prompt=c.get("negative_prompt"), num_inference_steps=c["steps"],
                  guidance_scale=GUIDANCE, width=c["width"], height=c["height"])
    if "control" in c:
        cc = c["control"]
        kwargs |= dict(image=open_rgb(out / cc["image"]), controlnet_conditioning_scale=cc["scale"],
                       control_guidance_start=cc["start"], control_guidance_end=cc["end"])
    if "loras" in c:
        names = []
        for i, (f, _) in enumerate(c["loras"]):
            names.append(f"l{i}")
            pipe.load_lora_weights(str(out / f), adapter_name=names[-1])
        pipe.set_adapters(names, adapter_weights=[s for _, s in c["loras"]])
    if "ip" in c:
        load_ip(pipe, out, c["ip"]["adapter"])
        pipe.set_ip_adapter_scale(c["ip"]["scale"])
        kwargs["ip_adapter_image"] = [[open_rgb(out / f) for f in c["ip"]["images"]]]
    latents = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(c["seed"]), output_type="latent").images
    pil = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(c["seed"]), output_type="pil").images[0]
    image = torch.from_numpy(np.array(pil)).float()
    # the image is the VAE decode of exactly these latents, rounded as numpy_to_pil does
    dec = pipe.vae.decode(latents / pipe.vae.config.scaling_factor).sample
    again = pipe.image_processor.postprocess(dec, output_type="np")[0]
    assert torch.equal(torch.from_numpy((again * 255).round().astype("uint8")).float(), image), c["name"]
    sched = pipe.scheduler
    info = dict(scheduler_class=type(sched).__name__, timesteps=[float(t) for t in sched.timesteps])
    return pipe, latents, image, info


def pipeline_records(base_folder, out, cns, tensors, meta, old_records):
    meta["cases"] = []
    results = {}
    for c in CASES:
        pipe, latents, image, info = run_case(c, base_folder, out, cns)
        results[c["name"]] = (latents, image)
        check_sane(c["name"], latents)
        p = f"gen.{c['name']}."
        tensors[p + "latents"] = latents.contiguous()
        tensors[p + "image_u8"] = image.contiguous()
        entry = dict(name=c["name"], prompt=c["prompt"], negative_prompt=c.get("negative_prompt"), seed=c["seed"],
                     steps=c["steps"], guidance_scale=GUIDANCE, sampler=c["sampler"], width=c["width"],
                     height=c["height"], control=c.get("control"), ip=c.get("ip"),
                     loras=[dict(file=f, strength=s) for f, s in c.get("loras", [])], **info,
                     tensors=dict(latents=p + "latents", image_u8=p + "image_u8"))
        meta["cases"].append(entry)
        print(f"{c['name']:22s} latents std {latents.std():.3f} mean {latents.mean():+.3f} | image mean "
              f"{image.mean():.1f} std {image.std():.1f} | {sum((image == v).float().mean().item() for v in (0, 255)):.3f} clipped")
        del pipe
    # base_check equals the pipeline fixture's euler_cat (same prompt/seed/steps/sampler/size)
    old = old_records.get("gen.0.latents")
    if old is not None:
        assert torch.equal(old, results["base_check"][0]), "base_check differs from pipeline fixture euler_cat"
    # every case differs from the base and from each other
    names = list(results)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if results[a][0].shape == results[b][0].shape and torch.equal(results[a][0], results[b][0]):
                raise SystemExit(f"{a} and {b} gave identical latents")
    return results


def check_clean_state(base_folder, out, cns, results):
    """Unloading LoRAs / IP-Adapter from a used pipeline gives back the base outputs exactly."""
    c = next(c for c in CASES if c["name"] == "full")
    pipe, _, _, _ = run_case(c, base_folder, out, cns)
    pipe.unload_lora_weights()
    pipe.unload_ip_adapter()
    pipe.unet.set_attn_processor(AttnProcessor2_0())
    base = next(c for c in CASES if c["name"] == "cn")
    pipe.scheduler = EulerDiscreteScheduler.from_config(pipe.scheduler.config)
    cc = base["control"]
    lat = pipe(prompt=base["prompt"], num_inference_steps=base["steps"], guidance_scale=GUIDANCE,
               width=base["width"], height=base["height"], image=open_rgb(out / cc["image"]),
               controlnet_conditioning_scale=cc["scale"], generator=torch.Generator("cpu").manual_seed(base["seed"]),
               output_type="latent").images
    same = torch.equal(lat, results["cn"][0])
    diff = (lat - results["cn"][0]).abs().max().item()
    print(f"after unload_lora_weights + unload_ip_adapter, case cn reruns {'identically' if same else f'with max diff {diff}'}")
    return dict(rerun_cn_after_unload_identical=same, max_abs_diff=diff,
                note="unload_lora_weights restores every weight bit-exactly (state dicts equal), yet a rerun "
                     "differs from a freshly loaded pipeline at float-rounding level (~2e-5 on latents of ~20); "
                     "unload_ip_adapter alone gives identical reruns. Every case here therefore runs on a pipeline "
                     "freshly loaded from disk.")


# ---------------------------------------------------------------------------------------------


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="tests/fixtures/workflow")
    ap.add_argument("--pipeline", default="tests/fixtures/pipeline/tiny-sdxl")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    base_folder = pathlib.Path(args.pipeline)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_grad_enabled(False)
    torch.set_num_threads(2)
    tensors, checks = {}, {}
    meta = dict(
        description="Reference outputs of diffusers (float32, CPU) for the tiny SDXL of "
                    f"{base_folder} with the ControlNets, IP-Adapters and LoRAs of this folder. All tensors in "
                    "records.safetensors are float32. Written by tools/make_workflow_fixtures.py.",
        versions=dict(torch=torch.__version__, torchvision=torchvision.__version__, diffusers=diffusers.__version__,
                      transformers=transformers.__version__, peft=peft.__version__,
                      safetensors=safetensors.__version__))

    make_images(out)
    pipe = load_base(base_folder)
    unet = pipe.unet
    old_records = load_file(base_folder.parent / "records.safetensors") if (base_folder.parent / "records.safetensors").exists() else {}

    g = gen_for("workflow-inputs")
    unet_inputs = dict(
        sample=torch.randn((2, 4, 8, 8), generator=g),
        timestep=torch.tensor([999.0, 261.0]),
        encoder_hidden_states=torch.randn((2, 77, CONTEXT), generator=g),
        text_embeds=torch.randn((2, 128), generator=g),
        time_ids=torch.tensor([[64.0, 64.0, 0, 0, 64.0, 64.0], [72.0, 80.0, 0, 0, 64.0, 64.0]]),
    )
    # ControlNets (the control image is needed for the scaling pass)
    cn_pipe_probe = StableDiffusionXLControlNetPipeline(**pipe.components, controlnet=ControlNetModel.from_unet(
        unet, conditioning_embedding_out_channels=HINT_CHANNELS), add_watermarker=False)
    cond = cn_pipe_probe.prepare_image(open_rgb(out / "control.png"), width=64, height=64, batch_size=2,
                                       num_images_per_prompt=1, device="cpu", dtype=torch.float32)
    del cn_pipe_probe
    scale_inputs = dict(unet_inputs, controlnet_cond=cond)
    cns, ratios = {}, {}
    for name, small in (("controlnet", False), ("controlnet-small", True)):
        cns[name], ratios[name] = build_controlnet(unet, small, scale_inputs)
        save_controlnet(cns[name], out / name)
    small_blocks = [len(a.transformer_blocks) for b in cns["controlnet-small"].down_blocks
                    for a in getattr(b, "attentions", [])]
    assert small_blocks == [0, 0], small_blocks
    save_cldm(cns["controlnet"], dict(unet.config), out / "controlnet-cldm.safetensors", checks)

    # IP-Adapter
    build_image_encoder(out / "image_encoder")
    ip_states = dict(plain=build_plain_adapter(unet, IMAGE_ENCODER_CONFIG["projection_dim"]),
                     plus=build_plus_adapter(unet, IMAGE_ENCODER_CONFIG["hidden_size"]))
    save_file({k: v.half().contiguous() for k, v in ip_states["plain"].items()}, out / "ip-adapter_tiny.safetensors")
    save_file({k: v.half().contiguous() for k, v in ip_states["plus"].items()}, out / "ip-adapter-plus_tiny.safetensors")
    meta["ip_adapter_layers"] = [dict(N=n, processor=name, hidden=h) for n, h, name in ip_layer_keys(unet)]

    # LoRAs
    meta["loras"] = {}
    for stem, builder in (("lora-kohya-ldm", lambda: build_kohya(pipe, KOHYA_LDM, "lora-kohya-ldm")),
                          ("lora-kohya-diffusers", lambda: build_kohya(pipe, KOHYA_DIFFUSERS, "lora-kohya-diffusers")),
                          ("lora-peft", lambda: build_peft(pipe, "lora-peft"))):
        state, spec, metadata = builder()
        path = out / f"{stem}.safetensors"
        save_lora(state, path, metadata)
        n = check_lora(pipe, path, spec, "check")
        pipe.unload_lora_weights()
        fused, worst = lora_fuse_records(pipe, path, spec, "check", tensors, stem)
        fresh = load_base(base_folder)
        restored = all(torch.equal(base_weight(pipe, s["component"], s["module"]),
                                   base_weight(fresh, s["component"], s["module"])) for s in spec)
        print(f"{stem}: {len(state)} tensors, {n} modules applied by diffusers with scale alpha/r; fuse_lora "
              f"matches W + s(alpha/r)BA to {worst:.1e} (relative); weights after unfuse+unload "
              f"{'identical' if restored else 'NOT identical'} to the base")
        pipe = fresh
        meta["loras"][stem] = dict(file=path.name, tensors=len(state), modules=spec, metadata=metadata,
                                   fused_strength=FUSE_STRENGTH, fused_records=fused,
                                   unfuse_restores_base_exactly=restored)
    del pipe

    component_records(base_folder, out, unet_inputs, cns, ip_states, tensors, meta)
    results = pipeline_records(base_folder, out, cns, tensors, meta, old_records)
    checks["clean_state"] = check_clean_state(base_folder, out, cns, results)
    checks["controlnet_residual_to_skip_std"] = ratios
    meta["checks"] = checks
    meta["conventions"] = dict(
        gen="latents = pipe(..., output_type='latent').images (final latents, before division by the VAE "
            "scaling factor); image_u8 = np.array(pipe(..., output_type='pil').images[0]) as float32 [H, W, 3] "
            "(values 0..255 = round(clamp(x/2+0.5, 0, 1)*255)), from a second call with a fresh generator. "
            "generator = torch.Generator('cpu').manual_seed(seed); scheduler = <sampler class>.from_config(the "
            "tiny-sdxl scheduler config); ControlNet cases use StableDiffusionXLControlNetPipeline built from "
            "the tiny-sdxl components + the ControlNet; LoRAs: load_lora_weights(file, adapter_name=l<i>) then "
            "set_adapters([...], adapter_weights=[strengths]); IP: load_ip_adapter(out, subfolder='', "
            "weight_name=..., image_encoder_folder='image_encoder'), set_ip_adapter_scale(scale), "
            "ip_adapter_image=[[images...]] (all images to the one adapter). negative_prompt null = absent "
            "(zero negative embeddings, force_zeros_for_empty_prompt).",
        lora_records="lora.<file stem>.<component>.<module>.weight = the weight after pipe.fuse_lora(lora_scale="
                     f"{FUSE_STRENGTH}) = W + {FUSE_STRENGTH}*(alpha/r)*up@down (float32); base.<component>."
                     "<module>.weight = W. Text-encoder module names are given with the text_model. level "
                     "(the names in tiny-sdxl's model.safetensors).",
    )
    save_file({k: v.float().contiguous() for k, v in tensors.items()}, out / "records.safetensors")
    (out / "records.json").write_text(json.dumps(meta, indent=1, ensure_ascii=False, allow_nan=False) + "\n")
    print("\nrecord max |value|:")
    for k in sorted(tensors):
        print(f"  {k:90s} {list(tensors[k].shape)!s:22s} {tensors[k].abs().max().item():10.4f}")
    total = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(f"wrote {out}: {total / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
