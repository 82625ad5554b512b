#!/usr/bin/env python3
"""Tiny SDXL-architecture UNets and their diffusers outputs, for vkdiff-unet's tests.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
safetensors 0.8.0. Setup:
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch diffusers safetensors
  /tmp/ref/bin/python tools/make_unet_fixtures.py [--out tests/fixtures/unet]

Each config gets a folder with:
  unet/config.json + weights in the diffusers layout (sdxl3: fp16 variant, sharded with an index;
      heads: bfloat16, one file),
  sd_xl_single_file.safetensors: the same weights under the original `model.diffusion_model.*`
      names (sdxl3: float16, as sd_xl_base_1.0 ships; heads: bfloat16); the names are checked by
      running diffusers' own single-file converter over them,
  ip_adapter.safetensors: random decoupled-attention weights `ip_adapter.N.to_k_ip/to_v_ip.weight`
      in the h94 layout, N numbered over diffusers' attention processors,
  io.safetensors: inputs (NCHW float32) and diffusers' float32 outputs for a batch of 2 with
      distinct timesteps, plain, with ControlNet residuals, with IP-Adapter tokens, and with both.

Every parameter is re-drawn (norm weights around 1, biases and the layers diffusers zero-initialises
non-zero), then rounded so that bfloat16, float16 and float32 copies hold identical values: the
reference runs in float32 on exactly the weights every stored copy holds.
"""
import argparse
import json
import pathlib

import torch
from diffusers import UNet2DConditionModel
from diffusers.models.attention_processor import AttnProcessor2_0, IPAdapterAttnProcessor2_0
from safetensors.torch import save_file

CONFIGS = {
    # SDXL's block layout: level 0 without attention, two resnets per down block, depth > 1 at
    # the last level; heads of 64 channels, 32 norm groups and 256-wide size embeddings, the
    # SDXL conventions single-file loaders assume because shapes cannot show them.
    "sdxl3": dict(
        config=dict(
            sample_size=16, in_channels=4, out_channels=4,
            down_block_types=["DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"],
            up_block_types=["CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "UpBlock2D"],
            block_out_channels=[32, 64, 64], layers_per_block=2,
            transformer_layers_per_block=[1, 1, 2], attention_head_dim=[1, 1, 1],
            cross_attention_dim=32, use_linear_projection=True, norm_num_groups=32,
            addition_embed_type="text_time", addition_time_embed_dim=256,
            projection_class_embeddings_input_dim=24 + 6 * 256,
        ),
        latent=(16, 24), tokens=77, text_embeds=24, ip_tokens=4,
        layouts=dict(diffusers="fp16-sharded", single_file=torch.float16),
    ),
    # Two levels, both with attention, different head counts and head sizes, one resnet per block.
    "heads": dict(
        config=dict(
            sample_size=8, in_channels=4, out_channels=4,
            down_block_types=["CrossAttnDownBlock2D", "CrossAttnDownBlock2D"],
            up_block_types=["CrossAttnUpBlock2D", "CrossAttnUpBlock2D"],
            block_out_channels=[32, 64], layers_per_block=1,
            transformer_layers_per_block=[1, 2], attention_head_dim=[2, 8],
            cross_attention_dim=48, use_linear_projection=True, norm_num_groups=8,
            addition_embed_type="text_time", addition_time_embed_dim=16,
            projection_class_embeddings_input_dim=40 + 6 * 16, flip_sin_to_cos=True, freq_shift=0,
        ),
        latent=(12, 20), tokens=10, text_embeds=40, ip_tokens=16,
        layouts=dict(diffusers="bf16", single_file=torch.bfloat16),
    ),
}


def representable_everywhere(t: torch.Tensor) -> torch.Tensor:
    """Rounds to bfloat16 and zeroes the few values float16 would then change (its subnormals)."""
    b = t.to(torch.bfloat16).float()
    return torch.where(b.half().float() == b, b, torch.zeros_like(b))


def redraw(unet: torch.nn.Module, gen: torch.Generator) -> None:
    with torch.no_grad():
        for name, p in unet.named_parameters():
            if p.ndim == 1:
                base = 1.0 if name.endswith("weight") else 0.0
                v = base + 0.1 * torch.randn(p.shape, generator=gen)
            else:
                fan_in = p[0].numel()
                v = torch.randn(p.shape, generator=gen) / fan_in**0.5
            p.copy_(representable_everywhere(v))


def cross_attention_processors(unet):
    """diffusers' processor names and hidden sizes of the attn2 layers, in processor order."""
    out = []
    for i, name in enumerate(unet.attn_processors.keys()):
        if name.endswith("attn2.processor"):
            module = unet.get_submodule(name[: -len(".processor")])
            out.append((i, name, module.to_q.out_features))
    return out


def run(unet, inputs, control=None, ip=None):
    ehs = inputs["encoder_hidden_states"]
    if ip is not None:
        ehs = (ehs, [ip["tokens"]])
    kwargs = {}
    if control is not None:
        kwargs = dict(down_block_additional_residuals=tuple(control["down"]), mid_block_additional_residual=control["mid"])
    with torch.no_grad():
        return unet(
            inputs["sample"], inputs["timestep"], encoder_hidden_states=ehs,
            added_cond_kwargs=dict(text_embeds=inputs["text_embeds"], time_ids=inputs["time_ids"]), **kwargs,
        ).sample


def skip_shapes(spec):
    """Shapes of the down path's skip tensors (ControlNet's residuals), in diffusers' order."""
    cfg = spec["config"]
    h, w = spec["latent"]
    shapes = [(cfg["block_out_channels"][0], h, w)]
    levels = len(cfg["block_out_channels"])
    for level, c in enumerate(cfg["block_out_channels"]):
        shapes += [(c, h, w)] * cfg["layers_per_block"]
        if level + 1 < levels:
            h, w = h // 2, w // 2
            shapes.append((c, h, w))
    return shapes, (cfg["block_out_channels"][-1], h, w)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="tests/fixtures/unet")
    args = ap.parse_args()
    for name, spec in CONFIGS.items():
        make(name, spec, pathlib.Path(args.out) / name)


def make(name, spec, out):
    gen = torch.Generator().manual_seed(sum(map(ord, name)))
    unet = UNet2DConditionModel(**spec["config"]).eval()
    unet.set_attn_processor(AttnProcessor2_0())
    redraw(unet, gen)
    cfg = spec["config"]
    h, w = spec["latent"]
    b = 2
    inputs = dict(
        sample=torch.randn((b, cfg["in_channels"], h, w), generator=gen),
        timestep=torch.tensor([999.0, 261.5]),
        encoder_hidden_states=torch.randn((b, spec["tokens"], cfg["cross_attention_dim"]), generator=gen),
        text_embeds=torch.randn((b, spec["text_embeds"]), generator=gen),
        time_ids=torch.tensor([[h * 8.0, w * 8.0, 0, 0, h * 8.0, w * 8.0], [1024.0, 768.0, 16.0, 32.0, h * 8.0, w * 8.0]]),
    )
    down_shapes, mid_shape = skip_shapes(spec)
    control = dict(
        down=[0.5 * torch.randn((b, *s), generator=gen) for s in down_shapes],
        mid=0.5 * torch.randn((b, *mid_shape), generator=gen),
    )
    ip_tokens = torch.randn((b, spec["ip_tokens"], cfg["cross_attention_dim"]), generator=gen)
    ip_scale = 0.7

    tensors = {k: v.contiguous() for k, v in inputs.items()}
    tensors |= {f"control_down.{i}": t for i, t in enumerate(control["down"])}
    tensors["control_mid"] = control["mid"]
    tensors["ip_tokens"] = ip_tokens
    tensors["ip_scale"] = torch.tensor([ip_scale])
    tensors["out_plain"] = run(unet, inputs)
    tensors["out_control"] = run(unet, inputs, control=control)

    # Decoupled cross-attention on every attn2, with random to_k_ip / to_v_ip.
    ip_weights = {}
    procs = {}
    crosses = {n: (i, hidden) for i, n, hidden in cross_attention_processors(unet)}
    for i, pname in enumerate(unet.attn_processors.keys()):
        if pname in crosses:
            _, hidden = crosses[pname]
            p = IPAdapterAttnProcessor2_0(hidden, cfg["cross_attention_dim"], num_tokens=(spec["ip_tokens"],), scale=ip_scale)
            with torch.no_grad():
                for lin in (p.to_k_ip[0], p.to_v_ip[0]):
                    lin.weight.copy_(representable_everywhere(torch.randn(lin.weight.shape, generator=gen) / cfg["cross_attention_dim"] ** 0.5))
            ip_weights[f"ip_adapter.{i}.to_k_ip.weight"] = p.to_k_ip[0].weight.detach().clone()
            ip_weights[f"ip_adapter.{i}.to_v_ip.weight"] = p.to_v_ip[0].weight.detach().clone()
            procs[pname] = p
        else:
            procs[pname] = AttnProcessor2_0()
    unet.set_attn_processor(procs)
    ip = dict(tokens=ip_tokens)
    tensors["out_ip"] = run(unet, inputs, ip=ip)
    tensors["out_both"] = run(unet, inputs, control=control, ip=ip)
    unet.set_attn_processor(AttnProcessor2_0())

    out.mkdir(parents=True, exist_ok=True)
    save_file({k: v.contiguous() for k, v in tensors.items()}, out / "io.safetensors")
    save_file(ip_weights, out / "ip_adapter.safetensors")
    layouts = spec["layouts"]
    if layouts["diffusers"] == "fp16-sharded":
        unet.half().save_pretrained(out / "unet", variant="fp16", max_shard_size="1MB")
        unet.float()
    else:
        unet.to(torch.bfloat16).save_pretrained(out / "unet")
        unet.float()
    if "single_file" in layouts:
        save_file(single_file_state(unet, layouts["single_file"]), out / "sd_xl_single_file.safetensors")
    print(name, "parameters:", sum(p.numel() for p in unet.parameters()),
          "out_plain std:", tensors["out_plain"].std().item())


def single_file_state(unet, dtype):
    """The original SDXL names, from diffusers' own diffusers-to-original conversion tables."""
    from diffusers.loaders.single_file_utils import convert_ldm_unet_checkpoint
    config = dict(unet.config)
    diffusers_state = unet.state_dict()
    # Invert diffusers' converter: convert every original name candidate and match the result.
    ldm = {}
    names = reference_ldm_names(config)
    for ldm_key, diffusers_key in names.items():
        ldm["model.diffusion_model." + ldm_key] = diffusers_state[diffusers_key].to(dtype)
    converted = convert_ldm_unet_checkpoint(
        {k: v.float() for k, v in ldm.items()}, config=config)
    assert set(converted) == set(diffusers_state), set(converted) ^ set(diffusers_state)
    for k, v in converted.items():
        assert torch.equal(v.float(), diffusers_state[k].float()), k
    return ldm


def reference_ldm_names(config):
    """Original name → diffusers name, following the block numbering of sdxl.md §2.2, for any
    number of levels and resnets per block. Checked above by diffusers' converter."""
    L = config["layers_per_block"]
    levels = len(config["block_out_channels"])
    top = {
        "time_embed.0": "time_embedding.linear_1", "time_embed.2": "time_embedding.linear_2",
        "label_emb.0.0": "add_embedding.linear_1", "label_emb.0.2": "add_embedding.linear_2",
        "input_blocks.0.0": "conv_in", "out.0": "conv_norm_out", "out.2": "conv_out",
    }
    resnet = {"in_layers.0": "norm1", "in_layers.2": "conv1", "emb_layers.1": "time_emb_proj",
              "out_layers.0": "norm2", "out_layers.3": "conv2", "skip_connection": "conv_shortcut"}
    prefixes = dict(top)
    for i in range(levels):
        for j in range(L):
            prefixes[f"input_blocks.{(L + 1) * i + j + 1}.0"] = (f"down_blocks.{i}.resnets.{j}", resnet)
            prefixes[f"input_blocks.{(L + 1) * i + j + 1}.1"] = f"down_blocks.{i}.attentions.{j}"
        if i + 1 < levels:
            prefixes[f"input_blocks.{(L + 1) * (i + 1)}.0.op"] = f"down_blocks.{i}.downsamplers.0.conv"
        for j in range(L + 1):
            prefixes[f"output_blocks.{(L + 1) * i + j}.0"] = (f"up_blocks.{i}.resnets.{j}", resnet)
            prefixes[f"output_blocks.{(L + 1) * i + j}.1"] = f"up_blocks.{i}.attentions.{j}"
        if i + 1 < levels:
            has_attn = "CrossAttn" in config["up_block_types"][i]
            prefixes[f"output_blocks.{(L + 1) * i + L}.{2 if has_attn else 1}.conv"] = f"up_blocks.{i}.upsamplers.0.conv"
    prefixes["middle_block.0"] = ("mid_block.resnets.0", resnet)
    prefixes["middle_block.1"] = "mid_block.attentions.0"
    prefixes["middle_block.2"] = ("mid_block.resnets.1", resnet)
    return _expand(prefixes, config)


def _expand(prefixes, config):
    unet_keys = UNet2DConditionModel(**{k: v for k, v in config.items() if not k.startswith("_")}).state_dict().keys()
    out = {}
    for ldm_prefix, target in prefixes.items():
        if isinstance(target, tuple):
            dprefix, renames = target
            for ldm_sub, dsub in renames.items():
                for suffix in ("weight", "bias"):
                    key = f"{dprefix}.{dsub}.{suffix}"
                    if key in unet_keys:
                        out[f"{ldm_prefix}.{ldm_sub}.{suffix}"] = key
        else:
            for key in unet_keys:
                if key.startswith(target + "."):
                    out[ldm_prefix + key[len(target):]] = key
    missing = set(unet_keys) - set(out.values())
    assert not missing, sorted(missing)[:5]
    return out


if __name__ == "__main__":
    main()
