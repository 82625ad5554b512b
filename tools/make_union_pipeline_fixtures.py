#!/usr/bin/env python3
"""ControlNet-Union through diffusers' StableDiffusionXLControlNetUnionPipeline on the tiny SDXL: one Union
model given two controls at once (control_mode [1, 3]: depth and thin lines), the same model given one, and
two Union models (MultiControlNetUnionModel: the N=6 folder and the N=8 ProMax file) each given its own
control with its own scale and range. The reference latents of pipeline/tests/union.rs and
tests/controlnets_cli.rs.

Uses the models tools/make_union_fixtures.py wrote (tests/fixtures/workflow/controlnet-union/,
controlnet-union-promax.safetensors) and the control images of tools/make_multi_controlnet_fixtures.py
(control.png, control-edges.png); writes union_pipeline.json (the cases) and union_pipeline.safetensors
(float32 latents, output_type='latent').

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
transformers 5.23.0, numpy 2.4.6, Pillow 13.0.0.
  /tmp/ref/bin/python tools/make_union_pipeline_fixtures.py"""
import json
import pathlib
import sys

import numpy as np
import torch
from safetensors.torch import load_file, save_file

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import make_workflow_fixtures as w  # noqa: E402
from diffusers import ControlNetUnionModel, StableDiffusionXLControlNetUnionPipeline  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "tests/fixtures/workflow"
BASE = ROOT / "tests/fixtures/pipeline/tiny-sdxl"

# Each net: its model, its images with their control_mode, its scale and range.
CASES = [
    dict(name="one_union_two_controls", prompt="a stone bridge over a river, morning fog", seed=31, steps=4,
         sampler="euler", width=64, height=64,
         nets=[dict(model="controlnet-union", images=["control.png", "control-edges.png"], modes=[1, 3],
                    scale=0.8, start=0.25, end=1.0)]),
    dict(name="one_union_one_control", prompt="a glass sculpture of a horse, museum lighting", seed=32, steps=4,
         sampler="euler_a", width=96, height=64,
         nets=[dict(model="controlnet-union", images=["control-edges.png"], modes=[3], scale=0.7, start=0.0,
                    end=0.75)]),
    dict(name="two_unions_own_windows", prompt="mushrooms on dark compost", seed=33, steps=4, sampler="euler",
         width=64, height=64,
         nets=[dict(model="controlnet-union", images=["control.png"], modes=[1], scale=0.6, start=0.0, end=0.5),
               dict(model="controlnet-union-promax.safetensors", images=["control-edges.png"], modes=[5],
                    scale=0.9, start=0.5, end=1.0)]),
]


def load_union(name):
    if name.endswith(".safetensors"):
        # The ProMax file has no config: the folder's, with its eight control types.
        config = {k: v for k, v in json.loads((OUT / "controlnet-union/config.json").read_text()).items()
                  if not k.startswith("_")}
        config["num_control_type"] = 8
        net = ControlNetUnionModel(**config)
        net.load_state_dict({k: v.float() for k, v in load_file(OUT / name).items()})
        return net.eval()
    return ControlNetUnionModel.from_pretrained(OUT / name, torch_dtype=torch.float32).eval()


def pipeline(nets):
    base = w.load_base(BASE)
    pipe = StableDiffusionXLControlNetUnionPipeline(**base.components, controlnet=nets,
                                                    force_zeros_for_empty_prompt=True, add_watermarker=False)
    pipe.set_progress_bar_config(disable=True)
    return pipe


def run(case, nets, generator_seed):
    pipe = pipeline([load_union(n["model"]) for n in nets] if len(nets) > 1 else load_union(nets[0]["model"]))
    pipe.scheduler = w.SAMPLERS[case["sampler"]].from_config(pipe.scheduler.config)
    images = [[w.open_rgb(OUT / i) for i in n["images"]] for n in nets]
    if len(nets) == 1:
        n = nets[0]
        args = dict(control_image=images[0], control_mode=n["modes"], controlnet_conditioning_scale=n["scale"],
                    control_guidance_start=n["start"], control_guidance_end=n["end"])
    else:
        args = dict(control_image=[i[0] for i in images], control_mode=[n["modes"][0] for n in nets],
                    controlnet_conditioning_scale=[n["scale"] for n in nets],
                    control_guidance_start=[n["start"] for n in nets],
                    control_guidance_end=[n["end"] for n in nets])
    return pipe(prompt=case["prompt"], num_inference_steps=case["steps"], guidance_scale=w.GUIDANCE,
                width=case["width"], height=case["height"],
                generator=torch.Generator("cpu").manual_seed(generator_seed), output_type="latent",
                **args).images


def main():
    torch.set_grad_enabled(False)
    torch.set_num_threads(2)
    tensors, cases = {}, []
    for c in CASES:
        latents = run(c, c["nets"], c["seed"])
        # The last control matters: without it the latents move.
        last = c["nets"][-1]
        fewer = c["nets"][:-1] if len(c["nets"]) > 1 else [dict(last, images=last["images"][:-1],
                                                                modes=last["modes"][:-1])]
        if fewer[0]["images"]:
            without = run(c, fewer, c["seed"])
            moved = ((latents - without).norm() / without.norm()).item()
            assert moved > 1e-3, f"{c['name']}: the last control moves the latents by only {moved:.1e}"
        else:
            moved = None
        name = f"union.{c['name']}.latents"
        tensors[name] = latents.contiguous()
        cases.append(dict(c, guidance_scale=w.GUIDANCE, tensors=dict(latents=name), last_control_moves=moved))
        print(f"{c['name']}: latents std {latents.std():.3f}; without the last control {moved}")
    save_file(tensors, OUT / "union_pipeline.safetensors")
    import diffusers
    import transformers
    meta = dict(description="diffusers' StableDiffusionXLControlNetUnionPipeline (one ControlNetUnionModel, or a "
                            "list: MultiControlNetUnionModel), float32 on the CPU; latents = output_type='latent'.",
                versions=dict(torch=torch.__version__, diffusers=diffusers.__version__,
                              transformers=transformers.__version__, numpy=np.__version__),
                cases=cases)
    (OUT / "union_pipeline.json").write_text(json.dumps(meta, indent=1) + "\n")
    print("wrote", OUT / "union_pipeline.json")


main()
