#!/usr/bin/env python3
"""diffusers' StableDiffusionXLPipeline on the CPU (torch, float32): text-encoding seconds, each
denoising step's seconds, VAE seconds and the process's peak resident memory for one text-to-image
run. vkdiff reads a step's time from the steps by its one rule (the median after the first).

Run by `vkdiff bench gen` in the same run as its own measurement: SDXL base's architecture (the
configs vkdiff builds in, passed as JSON) with random weights, the same size, steps, sampler (Euler)
and guidance. Prints one JSON line.
Setup: pip install torch diffusers transformers   (vkdiff runs it with $VKDIFF_REFERENCE_PYTHON, else python3)
Usage: gen_cpu_reference.py UNET_JSON CLIP_L_JSON BIGG_JSON VAE_JSON TOKENIZER_DIR SIZE STEPS
"""
import json
import resource
import sys
import time

import diffusers
import torch
from diffusers import AutoencoderKL, EulerDiscreteScheduler, StableDiffusionXLPipeline, UNet2DConditionModel
from transformers import CLIPTextConfig, CLIPTextModel, CLIPTextModelWithProjection, CLIPTokenizer


def random(module_fn):
    # Meta-device construction and one normal_ pass: the default initialisers of 3.5 B parameters
    # would take minutes.
    with torch.device("meta"):
        m = module_fn()
    m = m.to_empty(device="cpu").eval()
    with torch.no_grad():
        for p in m.parameters():
            p.normal_(0.0, 0.02)
        # to_empty leaves buffers uninitialised; CLIP's position ids must be 0..76 again.
        for name, b in m.named_buffers():
            if name.endswith("position_ids"):
                b.copy_(torch.arange(b.shape[-1]).expand_as(b))
    return m


def main():
    unet_cfg, l_cfg, g_cfg, vae_cfg = (json.loads(a) for a in sys.argv[1:5])
    tok_dir, size, steps = sys.argv[5], int(sys.argv[6]), int(sys.argv[7])
    torch.manual_seed(0)
    unet = random(lambda: UNet2DConditionModel(**unet_cfg))
    te1 = random(lambda: CLIPTextModel(CLIPTextConfig(**l_cfg)))
    te2 = random(lambda: CLIPTextModelWithProjection(CLIPTextConfig(**g_cfg)))
    vae = random(lambda: AutoencoderKL(**vae_cfg))
    tok1 = CLIPTokenizer(f"{tok_dir}/tokenizer/vocab.json", f"{tok_dir}/tokenizer/merges.txt", pad_token="<|endoftext|>", model_max_length=77)
    tok2 = CLIPTokenizer(f"{tok_dir}/tokenizer_2/vocab.json", f"{tok_dir}/tokenizer_2/merges.txt", pad_token="!", model_max_length=77)
    scheduler = EulerDiscreteScheduler(beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear",
                                       timestep_spacing="leading", steps_offset=1)
    pipe = StableDiffusionXLPipeline(vae, te1, te2, tok1, tok2, unet, scheduler, add_watermarker=False)
    prompt = "white button mushrooms on brown compost, top-down photo"
    stamps = []
    with torch.inference_mode():
        start = time.perf_counter()
        pipe.encode_prompt(prompt, do_classifier_free_guidance=True)
        text_s = time.perf_counter() - start
        start = time.perf_counter()
        latents = pipe(prompt, height=size, width=size, num_inference_steps=steps, guidance_scale=5.0, output_type="latent",
                       generator=torch.Generator("cpu").manual_seed(0),
                       callback_on_step_end=lambda p, i, t, kw: stamps.append(time.perf_counter()) or kw).images
        # Between step ends; the first from the call's start, less the prompts' encoding it repeats.
        steps_s = [stamps[0] - start - text_s] + [b - a for a, b in zip(stamps, stamps[1:])]
        start = time.perf_counter()
        vae.decode(latents / vae.config.scaling_factor)
        vae_s = time.perf_counter() - start
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux reports KiB
    print(json.dumps(dict(text_s=text_s, steps=steps_s, vae_s=vae_s, peak_mib=peak_mib, torch=torch.__version__,
                          diffusers=diffusers.__version__, threads=torch.get_num_threads())))


if __name__ == "__main__":
    main()
