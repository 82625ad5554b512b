#!/usr/bin/env python3
"""A tiny SDXL pipeline in both checkpoint layouts, and diffusers' outputs for it, for vkdiff's
end-to-end tests (tokenizers, text encoders, VAE, samplers, the whole text-to-image loop).

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
transformers 5.23.0, safetensors 0.8.0, open_clip_torch 3.3.0 (only for the BPE merges list).
Setup and rerun:
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch diffusers transformers safetensors open_clip_torch
  /tmp/ref/bin/python tools/make_pipeline_fixtures.py [--out tests/fixtures/pipeline]

Writes under --out:
  tiny-sdxl/: `StableDiffusionXLPipeline.save_pretrained` in float16 (model_index.json with
      force_zeros_for_empty_prompt true, scheduler/ with SDXL base's EulerDiscreteScheduler config,
      unet/, vae/, text_encoder/ (CLIPTextModel), text_encoder_2/ (CLIPTextModelWithProjection)),
      and tokenizer/ (pad "<|endoftext|>") / tokenizer_2/ (pad "!") exactly as
      clip_vocab.write_tokenizer writes them (the real CLIP vocabulary; no tokenizer.json).
  tiny-sdxl.safetensors: the same weights, float16, in the original single-file (sgm) layout:
      model.diffusion_model.* (UNet), first_stage_model.* (VAE, mid-attention q/k/v/proj_out as
      [C,C,1,1] convs, decoder up blocks numbered in reverse), conditioner.embedders.0.transformer.
      text_model.* (CLIP-L, HF names), conditioner.embedders.1.model.* (OpenCLIP names: q/k/v stacked
      by rows in attn.in_proj_*, text_projection stored as the matrix P of `x @ P`, i.e. the
      transpose of HF's text_projection.weight; plus an unused scalar logit_scale, as the real file
      has). All names are checked by running diffusers' own single-file converters
      (convert_ldm_unet_checkpoint, convert_ldm_vae_checkpoint, convert_ldm_clip_checkpoint,
      convert_open_clip_checkpoint) and comparing against the diffusers models' state dicts.
  records.safetensors + records.json: float32 reference outputs (token ids stored as float32, exact
      below 2^24) of the float32 CPU pipeline; records.json lists every case and its tensor names.

The tiny model follows the conventions single-file loaders rely on because shapes cannot show them:
attention heads of 64 channels (UNet, both text encoders; the VAE mid-attention is one head over its
64 channels), GroupNorm with 32 groups, 256-wide size (time-id) embeddings, and text encoders of
different widths (CLIP-L role 64 wide / 1 head / 3 layers / quick_gelu; bigG role 128 wide /
2 heads / 2 layers / gelu): UNet context = 64 + 128 = 192 channels, pooled = text_encoder_2's
projection (128). With different widths diffusers' own `from_single_file` tells the two CLIP models
apart (it does so by width) and rebuilds the same pipeline; that is checked too.
text_encoder/model.safetensors is rewritten under the `text_model.*` names the real SDXL file uses:
transformers 5 flattened CLIPTextModel and would save `embeddings.*` (it loads either).

Every parameter is re-drawn (norm weights around 1, biases and the layers diffusers zero-initialises
non-zero) and rounded so that float16 and float32 copies hold identical values: the reference runs in
float32 on exactly the weights the float16 files hold. To keep the repository small, the rows of both
token_embedding tables whose token id no fixture prompt produces (with either tokenizer, after
padding/truncation to 77) are zero; everything else is random. The VAE decoder's conv_out is drawn at
half scale so that few image pixels clamp to 0 or 1. All randomness goes through explicit
torch.Generator objects; token ids in the records come from transformers' CLIPTokenizer, which
encodes a literal "!" as tokenizer_2's pad token (id 0), not as BPE (sdxl.md §3.3).
"""
import argparse
import copy
import json
import math
import pathlib
import shutil
import sys
import tempfile

import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import clip_vocab  # noqa: E402
from make_unet_fixtures import redraw, representable_everywhere, single_file_state  # noqa: E402

import diffusers  # noqa: E402
import safetensors  # noqa: E402
import transformers  # noqa: E402
from diffusers import (  # noqa: E402
    AutoencoderKL, DDIMScheduler, DPMSolverMultistepScheduler, EulerAncestralDiscreteScheduler,
    EulerDiscreteScheduler, StableDiffusionXLPipeline, UNet2DConditionModel,
)
from diffusers.models.attention_processor import AttnProcessor2_0  # noqa: E402
from diffusers.loaders.single_file_utils import (  # noqa: E402
    convert_ldm_clip_checkpoint, convert_ldm_vae_checkpoint, convert_open_clip_checkpoint,
)
from safetensors.torch import save_file  # noqa: E402
from transformers import CLIPTextConfig, CLIPTextModel, CLIPTextModelWithProjection  # noqa: E402

# Heads of 64 channels. The two encoders have different widths, as CLIP-L (768) and bigG (1280) do:
# diffusers' single-file loader tells the two CLIP models apart by width, and a swapped context
# concatenation or pooled source then fails on shapes.
WIDTH_1 = 64  # text_encoder (CLIP-L role): 1 head
WIDTH_2 = 128  # text_encoder_2 (bigG role): 2 heads; also the pooled (projection) width

UNET_CONFIG = dict(
    sample_size=8, in_channels=4, out_channels=4,
    down_block_types=["DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"],
    up_block_types=["CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "UpBlock2D"],
    block_out_channels=[32, 64, 64], layers_per_block=1,
    # attention_head_dim is diffusers' (mis)name for the head count: 64 channels / 64 = 1 head.
    transformer_layers_per_block=[1, 1, 1], attention_head_dim=[1, 1, 1],
    cross_attention_dim=WIDTH_1 + WIDTH_2, use_linear_projection=True, norm_num_groups=32,
    addition_embed_type="text_time", addition_time_embed_dim=256,
    projection_class_embeddings_input_dim=WIDTH_2 + 6 * 256,
)

VAE_CONFIG = dict(
    in_channels=3, out_channels=3, latent_channels=4,
    down_block_types=["DownEncoderBlock2D"] * 4, up_block_types=["UpDecoderBlock2D"] * 4,
    block_out_channels=[32, 32, 64, 64], layers_per_block=2, act_fn="silu", norm_num_groups=32,
    sample_size=64, scaling_factor=0.13025, force_upcast=True,
)

# SDXL's text_encoder/config.json and text_encoder_2/config.json, shrunk. bos/eos/pad are the real
# (legacy) values: eos_token_id 2 makes transformers pool at argmax(ids), as open_clip does.
TE1_CONFIG = dict(
    vocab_size=49408, hidden_size=WIDTH_1, intermediate_size=128, num_hidden_layers=3,
    num_attention_heads=1, max_position_embeddings=77, hidden_act="quick_gelu", layer_norm_eps=1e-5,
    projection_dim=WIDTH_1, bos_token_id=0, eos_token_id=2, pad_token_id=1,
    attention_dropout=0.0, dropout=0.0, initializer_factor=1.0, initializer_range=0.02,
)
TE2_CONFIG = dict(
    TE1_CONFIG, hidden_size=WIDTH_2, intermediate_size=256, num_hidden_layers=2, num_attention_heads=2,
    hidden_act="gelu", projection_dim=WIDTH_2,  # diffusers splits in_proj by text_projection rows: = width
)

# stabilityai/stable-diffusion-xl-base-1.0 scheduler/scheduler_config.json
SCHEDULER_CONFIG = dict(
    beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear", num_train_timesteps=1000,
    prediction_type="epsilon", timestep_spacing="leading", steps_offset=1, interpolation_type="linear",
    use_karras_sigmas=False, sample_max_value=1.0, set_alpha_to_one=False, skip_prk_steps=True,
    clip_sample=False,
)

SAMPLERS = dict(
    euler=EulerDiscreteScheduler, euler_a=EulerAncestralDiscreteScheduler,
    dpmpp_2m=DPMSolverMultistepScheduler, ddim=DDIMScheduler,
)
KARRAS_CAPABLE = {"euler", "dpmpp_2m"}

LONG_PROMPT = (
    "an extremely detailed oil painting of a quiet harbour town at dawn, fishing boats with red and "
    "blue hulls resting on calm water, gulls circling above weathered wooden piers, mist rolling down "
    "the green hills behind white houses with slate roofs, a lighthouse on the rocky point, warm light "
    "on the clouds, reflections on the water, fine brush strokes, museum quality, dramatic composition, "
    "trending on an art forum, volumetric light, eight thousand pixels wide"
)

TEXT_PROMPTS = [
    "a photo of a cat",
    "",
    "Wow!! Really?! (masterpiece:1.2), [sharp] focus -- 100% #1 caf\u00e9's \"best\" shot...",
    LONG_PROMPT,
    "A Majestic LION standing on a ROCK; 4k, highly-detailed",
]

# name, prompt, negative_prompt (None: absent, zeros), seed, steps, guidance, sampler, karras, width, height
GEN_CASES = [
    ("euler_cat", "a photo of a cat", None, 0, 4, 5.0, "euler", False, 64, 64),
    ("euler_bike_neg", "a red bicycle leaning on a brick wall, golden hour", "blurry, low quality",
     42, 5, 7.5, "euler", False, 96, 64),
    ("euler_a_cat", "a photo of a cat", None, 0, 4, 5.0, "euler_a", False, 64, 64),
    ("euler_a_bigseed_neg", "a lighthouse in a storm", "ugly, watermark", 1234567890123, 6, 7.5,
     "euler_a", False, 96, 64),
    ("euler_karras", "A Majestic LION standing on a ROCK; 4k, highly-detailed", None, 42, 5, 5.0,
     "euler", True, 64, 64),
    ("dpmpp_2m", "a bowl of ramen, studio lighting", None, 7, 6, 5.0, "dpmpp_2m", False, 96, 64),
    ("dpmpp_2m_karras_neg", "a castle on a hill", "ugly", 0, 5, 7.5, "dpmpp_2m", True, 64, 64),
    ("ddim", "a watercolor fox in the snow", None, 42, 4, 5.0, "ddim", False, 96, 64),
    ("euler_nocfg_bang", "Wow!! Really?! (masterpiece:1.2), [sharp] focus", None, 3, 3, 1.0,
     "euler", False, 64, 64),
    ("dpmpp_2m_long_emptyneg", LONG_PROMPT, "", 1234567890123, 4, 5.0, "dpmpp_2m", False, 96, 64),
]


def text_encoder(cls, config, gen):
    model = cls(CLIPTextConfig(**config)).eval()
    redraw(model, gen)
    return model


def zero_unused_rows(model, used_ids):
    emb = model.get_input_embeddings().weight
    keep = torch.zeros(emb.shape[0], dtype=torch.bool)
    keep[sorted(used_ids)] = True
    with torch.no_grad():
        emb[~keep] = 0.0
    return int(keep.sum())


def token_ids(tok, prompt):
    return tok(prompt, padding="max_length", max_length=77, truncation=True).input_ids


def build(gen, tok1, tok2):
    used = set()
    prompts = set(TEXT_PROMPTS) | {c[1] for c in GEN_CASES} | {c[2] for c in GEN_CASES if c[2] is not None}
    for p in prompts:
        used |= set(token_ids(tok1, p)) | set(token_ids(tok2, p))

    te1 = text_encoder(CLIPTextModel, TE1_CONFIG, gen)
    te2 = text_encoder(CLIPTextModelWithProjection, TE2_CONFIG, gen)
    kept = [zero_unused_rows(te1, used), zero_unused_rows(te2, used)]

    unet = UNet2DConditionModel(**UNET_CONFIG).eval()
    unet.set_attn_processor(AttnProcessor2_0())
    redraw(unet, gen)

    vae = AutoencoderKL(**VAE_CONFIG).eval()
    redraw(vae, gen)
    with torch.no_grad():  # a gentler last conv: fewer pixels clamped to 0 or 1
        vae.decoder.conv_out.weight.mul_(0.5)

    # from_config keeps the keys EulerDiscreteScheduler does not take (set_alpha_to_one, clip_sample, ...),
    # as loading the real scheduler_config.json does; DDIMScheduler.from_config then picks them up.
    scheduler = EulerDiscreteScheduler.from_config(SCHEDULER_CONFIG)
    pipe = StableDiffusionXLPipeline(
        vae=vae, text_encoder=te1, text_encoder_2=te2, tokenizer=tok1, tokenizer_2=tok2, unet=unet,
        scheduler=scheduler, force_zeros_for_empty_prompt=True, add_watermarker=False,
    )
    pipe.set_progress_bar_config(disable=True)
    return pipe, sorted(used), kept


# ---------------------------------------------------------------------------------------------
# Single-file (sgm) layout


def vae_ldm_name(key, levels):
    """diffusers AutoencoderKL name → original name (sdxl.md §2.3)."""
    parts = key.split(".")
    side = parts[0]  # encoder / decoder / quant_conv / post_quant_conv
    rest = parts[1:]
    if side in ("quant_conv", "post_quant_conv"):
        return key
    if rest[0] == "down_blocks":
        i = int(rest[1])
        if rest[2] == "resnets":
            name = ["down", str(i), "block", rest[3]] + rest[4:]
        else:  # downsamplers.0.conv
            name = ["down", str(i), "downsample"] + rest[4:]
    elif rest[0] == "up_blocks":
        i = levels - 1 - int(rest[1])
        if rest[2] == "resnets":
            name = ["up", str(i), "block", rest[3]] + rest[4:]
        else:  # upsamplers.0.conv
            name = ["up", str(i), "upsample"] + rest[4:]
    elif rest[0] == "mid_block":
        if rest[1] == "resnets":
            name = ["mid", f"block_{int(rest[2]) + 1}"] + rest[3:]
        else:  # attentions.0
            sub = ".".join(rest[3:])
            sub = {"group_norm": "norm", "to_q": "q", "to_k": "k", "to_v": "v", "to_out.0": "proj_out"}[
                sub.rsplit(".", 1)[0]] + "." + sub.rsplit(".", 1)[1]
            name = ["mid", "attn_1", sub]
    elif rest[0] == "conv_norm_out":
        name = ["norm_out"] + rest[1:]
    else:
        name = rest
    out = ".".join([side] + name)
    return out.replace("conv_shortcut", "nin_shortcut")


def vae_single_file(vae, dtype):
    levels = len(vae.config.block_out_channels)
    state = vae.state_dict()
    ldm = {}
    for k, v in state.items():
        name = vae_ldm_name(k, levels)
        if ".mid.attn_1." in name and name.endswith("weight") and v.ndim == 2:
            v = v[:, :, None, None]  # Linear → 1×1 conv
        assert "first_stage_model." + name not in ldm, name
        ldm["first_stage_model." + name] = v.to(dtype).contiguous()
    converted = convert_ldm_vae_checkpoint({k: v.float() for k, v in ldm.items()}, dict(vae.config))
    check_equal("vae", converted, state)
    return ldm


CLIP_L_PREFIX = "conditioner.embedders.0.transformer."
BIGG_PREFIX = "conditioner.embedders.1.model."


def clip_l_single_file(te1, dtype):
    state = text_state(te1)
    ldm = {CLIP_L_PREFIX + k: v.to(dtype).contiguous() for k, v in state.items()}
    check_equal("text_encoder", convert_ldm_clip_checkpoint({k: v.float() for k, v in ldm.items()}), state)
    return ldm


def open_clip_single_file(te2, dtype):
    state = text_state(te2)
    tm = "text_model."
    out = {
        "token_embedding.weight": state[tm + "embeddings.token_embedding.weight"],
        "positional_embedding": state[tm + "embeddings.position_embedding.weight"],
        "ln_final.weight": state[tm + "final_layer_norm.weight"],
        "ln_final.bias": state[tm + "final_layer_norm.bias"],
        # open_clip computes x @ text_projection: the transpose of HF's Linear weight.
        "text_projection": state["text_projection.weight"].t(),
        "logit_scale": representable_everywhere(torch.tensor(4.6052)),  # ln(100); unused
    }
    for n in range(te2.config.num_hidden_layers):
        hf = f"{tm}encoder.layers.{n}."
        oc = f"transformer.resblocks.{n}."
        for a, b in (("layer_norm1", "ln_1"), ("layer_norm2", "ln_2"), ("self_attn.out_proj", "attn.out_proj"),
                     ("mlp.fc1", "mlp.c_fc"), ("mlp.fc2", "mlp.c_proj")):
            for s in ("weight", "bias"):
                out[f"{oc}{b}.{s}"] = state[f"{hf}{a}.{s}"]
        for s in ("weight", "bias"):
            out[f"{oc}attn.in_proj_{s}"] = torch.cat([state[f"{hf}self_attn.{p}_proj.{s}"] for p in "qkv"], 0)
    ldm = {BIGG_PREFIX + k: v.to(dtype).contiguous() for k, v in out.items()}
    converted = convert_open_clip_checkpoint(te2, {k: v.float() for k, v in ldm.items()}, prefix=BIGG_PREFIX)
    check_equal("text_encoder_2", converted, state)
    return ldm


def text_state(model):
    """The state dict under the names the real SDXL files use. transformers 5 flattened CLIPTextModel
    (no inner `text_model` module, so it saves `embeddings.*`); SDXL's text_encoder/model.safetensors
    and the single file's CLIP-L use `text_model.embeddings.*`, which transformers 5 still loads."""
    state = {k: v for k, v in model.state_dict().items() if not k.endswith("position_ids")}
    if not any(k.startswith("text_model.") for k in state):
        state = {"text_model." + k: v for k, v in state.items()}
    return state


def check_equal(what, converted, reference):
    converted = {k: v for k, v in converted.items() if not k.endswith("position_ids")}
    if set(converted) != set(reference):
        raise SystemExit(f"{what}: single-file names do not round-trip through diffusers' converter: "
                         f"{sorted(set(converted) ^ set(reference))[:10]}")
    for k, v in converted.items():
        if v.shape != reference[k].shape or not torch.equal(v.float(), reference[k].float()):
            raise SystemExit(f"{what}: {k} differs after diffusers' conversion ({tuple(v.shape)} vs "
                             f"{tuple(reference[k].shape)})")


# ---------------------------------------------------------------------------------------------
# Records


def scheduler_for(pipe, sampler, karras):
    cls = SAMPLERS[sampler]
    if sampler in KARRAS_CAPABLE:
        return cls.from_config(pipe.scheduler.config, use_karras_sigmas=karras)
    assert not karras, sampler
    return cls.from_config(pipe.scheduler.config)


def image_stats(img):
    return dict(mean=img.mean().item(), std=img.std().item(),
                saturated=((img <= 0.0) | (img >= 1.0)).float().mean().item())


def check_sane(name, t):
    if not torch.isfinite(t).all():
        raise SystemExit(f"{name}: non-finite values")
    if t.numel() > 1 and t.std().item() < 1e-4:
        raise SystemExit(f"{name}: (nearly) constant, std {t.std().item()}")


def records(pipe, tok1, tok2):
    tensors, meta = {}, dict(text=[], vae=[], gen=[])
    te1, te2, vae = pipe.text_encoder, pipe.text_encoder_2, pipe.vae
    with torch.no_grad():
        for i, prompt in enumerate(TEXT_PROMPTS):
            p = f"text.{i}."
            ids1 = torch.tensor([token_ids(tok1, prompt)])
            ids2 = torch.tensor([token_ids(tok2, prompt)])
            o1 = te1(ids1, output_hidden_states=True)
            o2 = te2(ids2, output_hidden_states=True)
            pe, _, ppe, _ = pipe.encode_prompt(prompt, device="cpu", do_classifier_free_guidance=False)
            t = {
                "ids_1": ids1[0].float(), "ids_2": ids2[0].float(),
                "hidden_1": o1.hidden_states[-2], "hidden_2": o2.hidden_states[-2], "pooled": o2.text_embeds,
                "prompt_embeds": pe, "pooled_prompt_embeds": ppe,
            }
            assert torch.equal(pe, torch.cat([t["hidden_1"], t["hidden_2"]], -1)), prompt
            assert torch.equal(ppe, t["pooled"]), prompt
            for k, v in t.items():
                if not k.startswith("ids"):
                    check_sane(p + k, v)
                tensors[p + k] = v.float().contiguous()
            untruncated = len(tok1(prompt).input_ids)
            meta["text"].append(dict(name=f"text.{i}", prompt=prompt, untruncated_tokens=untruncated,
                                     tensors={k: p + k for k in t}))
            print(f"text.{i}: tokens {untruncated:3d} ids_1[:6] {ids1[0, :6].tolist()} ids_2[:6] "
                  f"{ids2[0, :6].tolist()} hidden std {o1.hidden_states[-2].std():.3f}/"
                  f"{o2.hidden_states[-2].std():.3f} pooled std {o2.text_embeds.std():.3f}")

        g = torch.Generator("cpu").manual_seed(2024)
        latent = torch.randn((1, 4, 8, 12), generator=g)
        image = torch.rand((1, 3, 64, 96), generator=g) * 2 - 1
        decoded = vae.decode(latent).sample
        dist = vae.encode(image).latent_dist
        t = {"vae.latent": latent, "vae.decoded": decoded, "vae.image": image,
             "vae.encoded_mean": dist.mean, "vae.encoded_logvar": dist.logvar}
        for k, v in t.items():
            check_sane(k, v)
            tensors[k] = v.float().contiguous()
        meta["vae"].append(dict(
            name="vae", latent_seed=2024,
            note="decoded = vae.decode(latent).sample: post_quant_conv + decoder applied directly to "
                 "vae.latent (the pipeline divides by scaling_factor first; no clamping here). "
                 "encoded_mean/logvar = vae.encode(image).latent_dist.mean/.logvar (quant_conv output "
                 "split in two, logvar clamped to [-30, 20]), not multiplied by scaling_factor.",
            tensors=dict(latent="vae.latent", decoded="vae.decoded", image="vae.image",
                         encoded_mean="vae.encoded_mean", encoded_logvar="vae.encoded_logvar")))
        print(f"vae: decoded mean {decoded.mean():.3f} std {decoded.std():.3f}; encoded mean std "
              f"{dist.mean.std():.3f}, logvar mean {dist.logvar.mean():.3f}")

        base_config = dict(pipe.scheduler.config)
        for i, (name, prompt, neg, seed, steps, cfg, sampler, karras, w, h) in enumerate(GEN_CASES):
            pipe.scheduler = scheduler_for(pipe, sampler, karras)
            kwargs = dict(prompt=prompt, negative_prompt=neg, num_inference_steps=steps, guidance_scale=cfg,
                          width=w, height=h)
            latents = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(seed), output_type="latent").images
            sched = pipe.scheduler
            timesteps = [float(x) for x in sched.timesteps]
            sigmas = [float(x) for x in sched.sigmas] if hasattr(sched, "sigmas") else None
            img = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(seed), output_type="pt").images
            # The image is the VAE decode of exactly these latents.
            again = pipe.image_processor.postprocess(vae.decode(latents / vae.config.scaling_factor).sample,
                                                     output_type="pt")
            assert torch.equal(again, img), name
            assert latents.shape == (1, 4, h // 8, w // 8) and img.shape == (1, 3, h, w), name
            p = f"gen.{i}."
            check_sane(p + "latents", latents)
            check_sane(p + "image", img)
            tensors[p + "latents"] = latents.float().contiguous()
            tensors[p + "image"] = img.float().contiguous()
            st = image_stats(img)
            if st["saturated"] > 0.5:
                raise SystemExit(f"{name}: image saturated ({st})")
            meta["gen"].append(dict(
                name=name, index=i, prompt=prompt, negative_prompt=neg, seed=seed, steps=steps,
                guidance_scale=cfg, sampler=sampler, karras=karras, width=w, height=h,
                scheduler_class=type(sched).__name__, scheduler_config=json_safe(dict(sched.config)),
                timesteps=timesteps, sigmas=sigmas, init_noise_sigma=float(sched.init_noise_sigma),
                tensors=dict(latents=p + "latents", image=p + "image")))
            print(f"gen.{i} {name:24s} {sampler:8s} karras={int(karras)} seed={seed} steps={steps} cfg={cfg} "
                  f"{w}x{h}: latent std {latents.std():8.3f} mean {latents.mean():8.3f} | image mean "
                  f"{st['mean']:.3f} std {st['std']:.3f} saturated {st['saturated']:.3f}")
        pipe.scheduler = EulerDiscreteScheduler.from_config(base_config)

    by_name = {c["name"]: c for c in meta["gen"]}
    a, b = by_name["euler_cat"], by_name["euler_a_cat"]
    assert (a["seed"], a["steps"], a["prompt"]) == (b["seed"], b["steps"], b["prompt"])
    if torch.equal(tensors[a["tensors"]["latents"]], tensors[b["tensors"]["latents"]]):
        raise SystemExit("euler_a gave the same latents as euler: ancestral noise not drawn?")
    for i, c in enumerate(meta["gen"]):
        for c2 in meta["gen"][i + 1:]:
            if torch.equal(tensors[c["tensors"]["image"]], tensors[c2["tensors"]["image"]]) or (
                    c["width"] == c2["width"] and c["height"] == c2["height"]
                    and torch.equal(tensors[c["tensors"]["latents"]], tensors[c2["tensors"]["latents"]])):
                raise SystemExit(f"{c['name']} and {c2['name']} gave identical outputs")
    return tensors, meta


def json_safe(d):
    """A scheduler config as strict JSON: private keys (unordered `_use_default_values`) dropped,
    non-finite floats (DPMSolver's lambda_min_clipped = -inf) written as strings "inf"/"-inf"."""
    def value(v):
        if isinstance(v, float) and not math.isfinite(v):
            return str(v)
        if isinstance(v, (list, tuple)):
            return [value(x) for x in v]
        try:
            json.dumps(v, allow_nan=False)
        except (TypeError, ValueError):
            return str(v)
        return v
    return {k: value(v) for k, v in sorted(d.items()) if not k.startswith("_")}


# ---------------------------------------------------------------------------------------------


def save_diffusers(pipe, folder):
    if folder.exists():
        shutil.rmtree(folder)
    half = copy.deepcopy(pipe).to(torch.float16)
    half.save_pretrained(folder, safe_serialization=True)
    for sub, model in (("text_encoder", half.text_encoder), ("text_encoder_2", half.text_encoder_2)):
        files = list((folder / sub).glob("*.safetensors"))
        assert [f.name for f in files] == ["model.safetensors"], files
        save_file({k: v.contiguous() for k, v in text_state(model).items()}, files[0], metadata={"format": "pt"})
    for sub, pad in (("tokenizer", "<|endoftext|>"), ("tokenizer_2", "!")):
        shutil.rmtree(folder / sub)
        clip_vocab.write_tokenizer(folder / sub, pad)
    index = json.loads((folder / "model_index.json").read_text())
    assert index["force_zeros_for_empty_prompt"] is True, index


def check_reload(pipe, folder, single_file):
    """The saved folders hold exactly the float32 weights the records were made with."""
    tok1 = clip_vocab.hf_tokenizer(folder / "tokenizer")
    tok2 = clip_vocab.hf_tokenizer(folder / "tokenizer_2")
    loaded = StableDiffusionXLPipeline.from_pretrained(
        folder, torch_dtype=torch.float32, tokenizer=tok1, tokenizer_2=tok2, add_watermarker=False)
    for comp in ("unet", "vae", "text_encoder", "text_encoder_2"):
        a, b = getattr(pipe, comp).state_dict(), getattr(loaded, comp).state_dict()
        assert set(a) == set(b), comp
        for k in a:
            assert a[k].dtype == b[k].dtype and torch.equal(a[k], b[k]), (comp, k)
    assert dict(loaded.scheduler.config)["timestep_spacing"] == "leading"
    for sub in ("tokenizer", "tokenizer_2"):
        assert not (folder / sub / "tokenizer.json").exists()
    assert torch.equal(torch.tensor(tok1("Wow!! ok").input_ids), torch.tensor(pipe.tokenizer("Wow!! ok").input_ids))
    assert torch.equal(torch.tensor(tok2("Wow!! ok").input_ids), torch.tensor(pipe.tokenizer_2("Wow!! ok").input_ids))
    # The single file holds the same values, in float16, under the original names.
    with safetensors.safe_open(single_file, "pt") as f:
        keys = list(f.keys())
        dtypes = {f.get_slice(k).get_dtype() for k in keys}
    assert dtypes == {"F16"}, dtypes
    counts = {p: sum(k.startswith(p) for k in keys) for p in
              ("model.diffusion_model.", "first_stage_model.", CLIP_L_PREFIX, BIGG_PREFIX)}
    assert sum(counts.values()) == len(keys), counts
    # End to end: diffusers' own single-file pipeline loader (configs from the folder) rebuilds the
    # same models from the single file. (It tells the CLIP models apart by width only.)
    if WIDTH_1 == WIDTH_2:
        return counts
    single = StableDiffusionXLPipeline.from_single_file(
        str(single_file), config=str(folder), local_files_only=True, torch_dtype=torch.float32,
        tokenizer=tok1, tokenizer_2=tok2, add_watermarker=False)
    for comp in ("unet", "vae", "text_encoder", "text_encoder_2"):
        a, b = getattr(pipe, comp).state_dict(), getattr(single, comp).state_dict()
        a = {k: v for k, v in a.items() if not k.endswith("position_ids")}
        b = {k: v for k, v in b.items() if not k.endswith("position_ids")}
        if set(a) != set(b) or any(not torch.equal(a[k], b[k]) for k in a):
            raise SystemExit(f"from_single_file rebuilt a different {comp}")
    return counts


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="tests/fixtures/pipeline")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_grad_enabled(False)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        clip_vocab.write_tokenizer(tmp / "tokenizer", "<|endoftext|>")
        clip_vocab.write_tokenizer(tmp / "tokenizer_2", "!")
        tok1 = clip_vocab.hf_tokenizer(tmp / "tokenizer")
        tok2 = clip_vocab.hf_tokenizer(tmp / "tokenizer_2")

    gen = torch.Generator().manual_seed(sum(map(ord, "tiny-sdxl")))
    pipe, used, kept = build(gen, tok1, tok2)
    print("token ids used by the fixture prompts:", len(used), "rows kept:", kept)

    folder = out / "tiny-sdxl"
    save_diffusers(pipe, folder)
    single = {}
    single |= single_file_state(pipe.unet, torch.float16)
    single |= vae_single_file(pipe.vae, torch.float16)
    single |= clip_l_single_file(pipe.text_encoder, torch.float16)
    single |= open_clip_single_file(pipe.text_encoder_2, torch.float16)
    single_path = out / "tiny-sdxl.safetensors"
    save_file(single, single_path)
    counts = check_reload(pipe, folder, single_path)
    print("single-file tensors:", counts)

    tensors, meta = records(pipe, tok1, tok2)
    save_file(tensors, out / "records.safetensors")
    meta = dict(
        description="Reference outputs of diffusers' StableDiffusionXLPipeline (float32, CPU) on the tiny "
                    "SDXL in tiny-sdxl/ (== tiny-sdxl.safetensors). Tensors in records.safetensors, all "
                    "float32 (token ids too). Written by tools/make_pipeline_fixtures.py.",
        versions=dict(torch=torch.__version__, diffusers=diffusers.__version__,
                      transformers=transformers.__version__, safetensors=safetensors.__version__),
        conventions=dict(
            text="ids_N = tokenizer_N(prompt, padding='max_length', max_length=77, truncation=True); "
                 "hidden_N = text_encoder_N(ids_N, output_hidden_states=True).hidden_states[-2]; "
                 "pooled = text_encoder_2(ids_2).text_embeds; prompt_embeds/pooled_prompt_embeds = "
                 "pipe.encode_prompt(prompt, do_classifier_free_guidance=False) (= cat(hidden_1, hidden_2)).",
            gen="latents = pipe(..., output_type='latent').images (final latents, before the division by "
                "scaling_factor); image = pipe(..., output_type='pt').images in [0, 1] from a second call "
                "with a fresh generator of the same seed; generator = torch.Generator('cpu').manual_seed(seed); "
                "scheduler = <scheduler_class>.from_config(SDXL euler config[, use_karras_sigmas=karras]); "
                "negative_prompt null = absent: zero negative context and pooled (force_zeros_for_empty_prompt); "
                "negative_prompt '' is encoded like any prompt. time_ids = [height, width, 0, 0, height, width].",
            token_embedding="rows of both token_embedding tables for ids not in any fixture prompt's ids_1/ids_2 "
                            "are zero",
        ),
        used_token_ids=used,
        **meta,
    )
    (out / "records.json").write_text(json.dumps(meta, indent=1, ensure_ascii=False, allow_nan=False) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
