#!/usr/bin/env python3
"""diffusers' own pipeline for the paper's image, beside `vkdiff bench report`'s: SDXL with the
depth ControlNet (scale 0.5) and a plain SDXL IP-Adapter over two style images (scale 0.6),
random weights of the real architectures (the configs vkdiff passes on standard input), Euler,
guidance 5, decoded by the VAE to a PIL image. Seconds per image as a set pays them after its
first: the prompts and the style images are encoded once per set (their embeddings are given,
as vkdiff's set encodes them once), and LoRAs fused into the weights cost nothing per image (not
loaded). Each image's seconds and each of its STEPS_TIMED steps' seconds are printed as measured:
vkdiff counts the suite's steps that did not run by its one rule (the median of the timed steps
after the first), the rule its own images are counted by. With WARM_UP 1 an untimed image comes
first, as vkdiff's full suite makes one (its quick suite makes none, and passes 0). The models run
at their best (tools/reference_timing.py), the UNet's projections unfused where an IP-Adapter's
processors must stay. Prints one JSON line: {"images": [{"seconds": S, "steps": [S, ...]}, ...],
"torch", "diffusers", "where", "settings", "host", "clocks"}.

Standard input: {"unet": {...}, "controlnet": {...}, "vae": {...}, "scheduler": {...},
                 "ip_adapter": true}   (false: no IP-Adapter, as the workflow timed has none)
Setup: pip install torch diffusers transformers   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON)
Usage: workflow_reference.py SIZE STEPS_TIMED RUNS WARM_UP [cpu | cuda f16 | cuda f32]
"""
import json
import sys
import time

import diffusers
import torch
from diffusers import (AutoencoderKL, ControlNetModel, EulerDiscreteScheduler,
                       StableDiffusionXLControlNetPipeline, UNet2DConditionModel)
from diffusers.models.attention_processor import AttnProcessor2_0, IPAdapterAttnProcessor2_0
from diffusers.models.embeddings import ImageProjection, MultiIPAdapterImageProjection
from PIL import Image

import reference_timing as rt


def random(module, device, dtype):
    """Random weights without the slow default initialisers of billion-parameter models."""
    module = module.to_empty(device=device).to(dtype).eval()
    with torch.no_grad():
        for p in module.parameters():
            p.normal_(0.0, 0.02)
    return module


def with_ip_adapter(unet, image_embed_dim=1024, tokens=4, scale=0.6):
    """A plain SDXL IP-Adapter (h94's ip-adapter_sdxl layout): an image projection to `tokens`
    context tokens per image, and key/value projections of them in every cross-attention."""
    channels = unet.config.block_out_channels
    processors = {}
    for name in unet.attn_processors:
        if name.endswith("attn1.processor"):
            processors[name] = AttnProcessor2_0()
            continue
        if name.startswith("mid_block"):
            hidden = channels[-1]
        elif name.startswith("up_blocks"):
            hidden = list(reversed(channels))[int(name.split(".")[1])]
        else:
            hidden = channels[int(name.split(".")[1])]
        processors[name] = IPAdapterAttnProcessor2_0(hidden_size=hidden, cross_attention_dim=unet.config.cross_attention_dim,
                                                     scale=scale, num_tokens=tokens)
    unet.set_attn_processor(processors)
    projection = ImageProjection(cross_attention_dim=unet.config.cross_attention_dim, image_embed_dim=image_embed_dim,
                                 num_image_text_embeds=tokens)
    unet.encoder_hid_proj = MultiIPAdapterImageProjection([projection])
    unet.config.encoder_hid_dim_type = "ip_image_proj"
    return unet


def main():
    size, steps_timed, runs, warm_up = (int(a) for a in sys.argv[1:5])
    device = sys.argv[5] if len(sys.argv) > 5 else "cpu"
    dtype = torch.float16 if device == "cuda" and sys.argv[6:7] == ["f16"] else torch.float32
    configs = json.load(sys.stdin)
    torch.manual_seed(0)
    with torch.device("meta"):
        unet = UNet2DConditionModel(**configs["unet"])
        if configs.get("ip_adapter", True):
            unet = with_ip_adapter(unet)
        controlnet = ControlNetModel(**configs["controlnet"])
        vae = AutoencoderKL(**configs["vae"])
    unet, controlnet, vae = (random(m, device, dtype) for m in (unet, controlnet, vae))
    settings = rt.best_settings(device)
    unet = rt.at_best(unet, settings, fuse=not configs.get("ip_adapter", True))
    controlnet, vae = (rt.at_best(m, settings) for m in (controlnet, vae))
    clocks = [rt.gpu_clocks()] if device == "cuda" else None
    scheduler = EulerDiscreteScheduler.from_config(configs["scheduler"])
    pipe = StableDiffusionXLControlNetPipeline(vae=vae, text_encoder=None, text_encoder_2=None, tokenizer=None,
                                               tokenizer_2=None, unet=unet, controlnet=controlnet,
                                               scheduler=scheduler, add_watermarker=False)
    pipe.set_progress_bar_config(disable=True)
    make = dict(device=device, dtype=dtype)
    context = configs["unet"]["cross_attention_dim"]
    pooled = configs["unet"]["projection_class_embeddings_input_dim"] - 6 * configs["unet"]["addition_time_embed_dim"]
    # The set's prompt and two style images, encoded once: negative first, as guidance takes them.
    embeds = dict(prompt_embeds=torch.randn(1, 77, context, **make), negative_prompt_embeds=torch.zeros(1, 77, context, **make),
                  pooled_prompt_embeds=torch.randn(1, pooled, **make), negative_pooled_prompt_embeds=torch.zeros(1, pooled, **make))
    if configs.get("ip_adapter", True):
        embeds["ip_adapter_image_embeds"] = [torch.cat([torch.zeros(1, 2, 1024, **make), torch.randn(1, 2, 1024, **make)])]
    depth = Image.fromarray((torch.arange(size).repeat(size, 1) * 255 // size).to(torch.uint8).numpy()).convert("RGB")
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    marks = []

    def mark(pipe, step, timestep, kwargs):
        sync()
        marks.append(time.perf_counter())
        return kwargs

    def image():
        marks.clear()
        sync()
        start = time.perf_counter()
        marks.append(start)
        pipe(image=depth, num_inference_steps=steps_timed, guidance_scale=5.0, controlnet_conditioning_scale=0.5,
             height=size, width=size, callback_on_step_end=mark, **embeds)
        sync()
        # Between step ends; the first from the call's start, so it holds the call's preparation.
        return dict(seconds=time.perf_counter() - start, steps=[b - a for a, b in zip(marks, marks[1:])])

    with torch.inference_mode():
        if warm_up:
            image()  # picks kernels and grows the allocator
        images = [image() for _ in range(runs)]
    name = str(dtype).removeprefix("torch.")
    where = f"{torch.cuda.get_device_name()} {name}" if device == "cuda" else f"CPU {name}, {torch.get_num_threads()} threads"
    if clocks:
        clocks.append(rt.gpu_clocks())
    print(json.dumps(dict(images=images, torch=torch.__version__, diffusers=diffusers.__version__, where=where,
                          settings=settings, host=rt.host(device), clocks=clocks)))


if __name__ == "__main__":
    main()
