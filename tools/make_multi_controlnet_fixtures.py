#!/usr/bin/env python3
"""Two ControlNets at once on the tiny SDXL, as diffusers' MultiControlNetModel sums them: each net's
residuals scaled by its controlnet_conditioning_scale and kept only inside its own
[control_guidance_start, control_guidance_end], then added. The reference latents of
pipeline/tests/multi_controlnet.rs.

Uses the models tools/make_workflow_fixtures.py wrote (tests/fixtures/workflow: controlnet,
controlnet-small, control.png) and the tiny SDXL; writes control-edges.png (the second net's image:
white where control.png's brightness changes by more than 8 levels to a 4-neighbour, else black),
multi_controlnet.json (the cases) and multi_controlnet.safetensors (float32 latents).

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
transformers 5.23.0, numpy 2.4.6, Pillow 13.0.0.
  /tmp/ref/bin/python tools/make_multi_controlnet_fixtures.py"""
import json
import pathlib
import sys

import numpy as np
import torch
from PIL import Image
from safetensors.torch import save_file

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import make_workflow_fixtures as w  # noqa: E402
from diffusers import ControlNetModel  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "tests/fixtures/workflow"
BASE = ROOT / "tests/fixtures/pipeline/tiny-sdxl"

CASES = [
    dict(name="two_nets", prompt="a stone bridge over a river, morning fog", seed=21, steps=4, sampler="euler",
         width=64, height=64,
         controls=[dict(model="controlnet", image="control.png", scale=0.7, start=0.0, end=1.0),
                   dict(model="controlnet-small", image="control-edges.png", scale=0.5, start=0.25, end=0.75)]),
    dict(name="two_nets_own_windows", prompt="a glass sculpture of a horse, museum lighting", seed=22, steps=4,
         sampler="euler_a", width=96, height=64,
         controls=[dict(model="controlnet", image="control.png", scale=1.0, start=0.0, end=0.5),
                   dict(model="controlnet-small", image="control-edges.png", scale=0.8, start=0.5, end=1.0)]),
]


def write_edges():
    grey = np.asarray(Image.open(OUT / "control.png").convert("L")).astype(int)
    edge = np.zeros(grey.shape, bool)
    edge[:, :-1] |= np.abs(grey[:, 1:] - grey[:, :-1]) > 8
    edge[:-1, :] |= np.abs(grey[1:, :] - grey[:-1, :]) > 8
    Image.fromarray(np.repeat((edge * 255).astype(np.uint8)[..., None], 3, axis=2)).save(OUT / "control-edges.png")


def main():
    torch.set_grad_enabled(False)
    torch.set_num_threads(2)
    write_edges()
    nets = {n: ControlNetModel.from_pretrained(OUT / n, variant="fp16", torch_dtype=torch.float32)
            for n in ("controlnet", "controlnet-small")}
    tensors, cases = {}, []
    for c in CASES:
        pipe = w.cn_pipeline(BASE, [nets[k["model"]] for k in c["controls"]])
        pipe.scheduler = w.SAMPLERS[c["sampler"]].from_config(pipe.scheduler.config)
        controls = c["controls"]
        latents = pipe(prompt=c["prompt"], num_inference_steps=c["steps"], guidance_scale=w.GUIDANCE,
                       width=c["width"], height=c["height"],
                       image=[w.open_rgb(OUT / k["image"]) for k in controls],
                       controlnet_conditioning_scale=[k["scale"] for k in controls],
                       control_guidance_start=[k["start"] for k in controls],
                       control_guidance_end=[k["end"] for k in controls],
                       generator=torch.Generator("cpu").manual_seed(c["seed"]), output_type="latent").images
        # Each net matters: the case without its second net moves the latents.
        alone = pipe.controlnet.nets[0]
        single = w.cn_pipeline(BASE, alone)
        single.scheduler = w.SAMPLERS[c["sampler"]].from_config(single.scheduler.config)
        first = controls[0]
        without = single(prompt=c["prompt"], num_inference_steps=c["steps"], guidance_scale=w.GUIDANCE,
                         width=c["width"], height=c["height"], image=w.open_rgb(OUT / first["image"]),
                         controlnet_conditioning_scale=first["scale"], control_guidance_start=first["start"],
                         control_guidance_end=first["end"],
                         generator=torch.Generator("cpu").manual_seed(c["seed"]), output_type="latent").images
        moved = ((latents - without).norm() / without.norm()).item()
        assert moved > 1e-3, f"{c['name']}: the second net changes the latents by only {moved:.1e}"
        name = f"multi.{c['name']}.latents"
        tensors[name] = latents.contiguous()
        cases.append(dict(c, guidance_scale=w.GUIDANCE, negative_prompt=None, ip=None, loras=[],
                          tensors=dict(latents=name), second_net_moves=moved))
        print(f"{c['name']}: latents std {latents.std():.3f}; without the second net {moved:.2e} relative")
    save_file(tensors, OUT / "multi_controlnet.safetensors")
    import diffusers
    import transformers
    meta = dict(description="diffusers' StableDiffusionXLControlNetPipeline with a list of ControlNets "
                            "(MultiControlNetModel), float32 on the CPU; latents = output_type='latent'.",
                versions=dict(torch=torch.__version__, diffusers=diffusers.__version__,
                              transformers=transformers.__version__, numpy=np.__version__),
                cases=cases)
    (OUT / "multi_controlnet.json").write_text(json.dumps(meta, indent=1) + "\n")
    print("wrote", OUT / "multi_controlnet.json")


main()
