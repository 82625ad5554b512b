#!/usr/bin/env python3
"""A second tiny VAE for `--vae`, and diffusers' images with it swapped into the tiny SDXL.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0, diffusers 0.42.1,
transformers 5.24.0, safetensors 0.8.0.
Setup and rerun (after tools/make_pipeline_fixtures.py, whose tiny SDXL it reads):
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch diffusers transformers safetensors
  /tmp/ref/bin/python tools/make_vae_swap_fixtures.py [--out tests/fixtures/vae_swap]

Writes under --out:
  tiny-vae/: the VAE as madebyollin/sdxl-vae-fp16-fix keeps it: `AutoencoderKL.save_pretrained`
      (config.json, diffusion_pytorch_model.safetensors in float16) with `force_upcast: false`
      and a scaling factor of 0.2 (not the tiny SDXL's 0.13025, so a run that kept the model's
      own factor shows), and sdxl_vae.safetensors: the same weights in the original layout with
      no prefix, as a standalone VAE file stores them.
  records.safetensors + records.json: float32 images (CHW in [0, 1], as the pipeline returns them
      with output_type='pt') and final latents of StableDiffusionXLPipeline.from_pretrained(
      tiny-sdxl, vae=AutoencoderKL.from_pretrained(tiny-vae)) in float32 on the CPU.
"""
import argparse
import json
import pathlib
import shutil
import sys

import diffusers
import safetensors
import torch
import transformers
from diffusers import AutoencoderKL, StableDiffusionXLPipeline
from safetensors.torch import save_file

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from make_pipeline_fixtures import vae_single_file  # noqa: E402

CASES = [
    # name, prompt, seed, steps, cfg, width, height
    ("cube", "a red cube on a wooden table", 7, 4, 5.0, 64, 64),
    ("mushrooms", "white button mushrooms on dark compost", 11, 3, 1.0, 96, 64),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="tests/fixtures/pipeline/tiny-sdxl")
    ap.add_argument("--out", default="tests/fixtures/vae_swap")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    torch.set_grad_enabled(False)

    base = AutoencoderKL.from_pretrained(args.model, subfolder="vae")
    config = dict(base.config)
    config.update(force_upcast=False, scaling_factor=0.2)
    torch.manual_seed(sum(map(ord, "tiny-vae")))
    vae = AutoencoderKL.from_config(config)
    folder = out / "tiny-vae"
    if folder.exists():
        shutil.rmtree(folder)
    vae.to(torch.float16).save_pretrained(folder)
    single = {k.removeprefix("first_stage_model."): v for k, v in vae_single_file(vae, torch.float16).items()}
    save_file(single, folder / "sdxl_vae.safetensors")

    # The reference reads back the saved (float16-rounded) weights, as vkdiff does.
    vae = AutoencoderKL.from_pretrained(folder, torch_dtype=torch.float32)
    assert vae.config.force_upcast is False and vae.config.scaling_factor == 0.2
    pipe = StableDiffusionXLPipeline.from_pretrained(args.model, vae=vae, torch_dtype=torch.float32)
    tensors, cases = {}, []
    for i, (name, prompt, seed, steps, cfg, w, h) in enumerate(CASES):
        kwargs = dict(prompt=prompt, num_inference_steps=steps, guidance_scale=cfg, width=w, height=h)
        latents = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(seed), output_type="latent").images
        image = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(seed), output_type="pt").images
        again = pipe.image_processor.postprocess(vae.decode(latents / 0.2).sample, output_type="pt")
        assert torch.equal(again, image), name
        tensors[f"{name}.latents"] = latents.float().contiguous()
        tensors[f"{name}.image"] = image.float().contiguous()
        cases.append(dict(name=name, prompt=prompt, seed=seed, steps=steps, guidance_scale=cfg, sampler="euler",
                          width=w, height=h))
        print(f"{name}: image mean {image.mean():.3f} std {image.std():.3f}")
    save_file(tensors, out / "records.safetensors")
    meta = dict(
        description="StableDiffusionXLPipeline.from_pretrained(tiny-sdxl, vae=AutoencoderKL.from_pretrained("
                    "tiny-vae)) in float32 on the CPU, euler (the model's scheduler), generator "
                    "torch.Generator('cpu').manual_seed(seed), no negative prompt. <name>.image: "
                    "output_type='pt' images in [0, 1], CHW; <name>.latents: output_type='latent'. "
                    "Written by tools/make_vae_swap_fixtures.py.",
        versions=dict(torch=torch.__version__, diffusers=diffusers.__version__,
                      transformers=transformers.__version__, safetensors=safetensors.__version__),
        cases=cases,
    )
    (out / "records.json").write_text(json.dumps(meta, indent=1) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
