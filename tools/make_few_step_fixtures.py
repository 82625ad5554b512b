#!/usr/bin/env python3
"""diffusers' outputs for the few-step recipes (SDXL-Lightning, Hyper-SD, LCM, TCD, Turbo, DMD2) on the tiny SDXL of
tests/fixtures/pipeline/tiny-sdxl, with the depth ControlNet of tests/fixtures/workflow and the init image of
tests/fixtures/compat:

  - every sampler under its recipe's settings (the scheduler built as the model cards build it,
    `XScheduler.from_config(pipe.scheduler.config, timestep_spacing=..., prediction_type=...)`, then
    `pipe(num_inference_steps=N)` or `pipe(timesteps=[...])`, `eta=` for TCD, guidance 0, 1 or above):
    text-to-image alone, through StableDiffusionXLControlNetPipeline (with control_guidance_start/end that
    cut the few steps), and through StableDiffusionXLImg2ImgPipeline (strength over the trailing schedule);
  - the distillation LoRAs in the layout their published files use (key names, dtypes and header read from the
    files' sizes, DMD2's extract_lora_module.py and third-party key dumps; see DISTILLATION_LORAS): kohya names over
    diffusers module paths (`lora_unet_<path>.lora_down.weight`, `.lora_up.weight`, a 0-dim `.alpha`) on every
    attention projection, feed-forward, proj_in/out, resnet conv1/conv2/conv_shortcut/time_emb_proj and
    down/upsampler conv of the UNet, no text encoder; alpha 8 (DMD2's and Lightning's; the rank here is 16 where
    theirs is 64); float16 with no metadata (Lightning, DMD2, LCM, TCD) or float32 under {"format": "pt"}
    (Hyper-SD). Each is checked wrapped by diffusers' load_lora_weights on every module with scale alpha/r, and
    fuse_lora's weights recorded for four modules (records.json "loras", read as tests/fixtures/workflow's); each
    also runs its recipe through the pipeline, DMD2's beside the workflow's two style LoRAs
    (load_lora_weights per adapter, set_adapters with their strengths);
  - a UNet swapped in as Lightning's and DMD2's model cards do it (`UNet2DConditionModel.from_config(base unet
    config)`, `load_state_dict(file)`, the pipeline built with `unet=`): a tiny "distilled" UNet of the base's
    architecture with its weights re-drawn, stored in the diffusers layout (unet-diffusers.safetensors, as
    sdxl_lightning_*_unet.safetensors is), the original layout without a prefix (unet-original.safetensors, as
    ComfyUI's diffusion_models files), and as a torch .bin state dict (unet-diffusers.bin, as DMD2's
    dmd2_sdxl_4step_unet_fp16.bin is); each case names the file it ran with, all three hold the same
    float16 weights.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1, transformers
5.25.0, safetensors 0.8.0, pillow 12 (2026-12-04, a 2-core AMD EPYC).
Setup and rerun (the tiny pipeline, workflow and compat fixtures must exist; they are loaded, not regenerated):
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch diffusers transformers safetensors pillow
  /tmp/ref/bin/python tools/make_few_step_fixtures.py [--out tests/fixtures/few_step]

Writes under --out: records.json (every case's settings under vkdiff's names, as tests/fixtures/compat/records.json),
records.safetensors (float32 latents and 8-bit images as float32), the three UNet files.
"""
import argparse
import json
import pathlib
import sys

import numpy as np
import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import make_workflow_fixtures as wf  # noqa: E402
from make_unet_fixtures import redraw, single_file_state  # noqa: E402

import diffusers  # noqa: E402
import safetensors  # noqa: E402
import transformers  # noqa: E402
from diffusers import (  # noqa: E402
    ControlNetModel, DDIMScheduler, DPMSolverMultistepScheduler, EulerAncestralDiscreteScheduler,
    EulerDiscreteScheduler, LCMScheduler, StableDiffusionXLControlNetPipeline, StableDiffusionXLImg2ImgPipeline,
    StableDiffusionXLPipeline, TCDScheduler, UNet2DConditionModel,
)
from safetensors.torch import load_file, save_file  # noqa: E402

SCHEDULERS = dict(euler=EulerDiscreteScheduler, euler_a=EulerAncestralDiscreteScheduler,
                  dpmpp_2m=DPMSolverMultistepScheduler, ddim=DDIMScheduler, lcm=LCMScheduler, tcd=TCDScheduler)
PROMPT = "a red barn in a green field"
CONTROL = dict(model="controlnet", image="control.png", scale=0.8)
UNET_FILES = ["unet-diffusers.safetensors", "unet-original.safetensors", "unet-diffusers.bin"]
# (file under --out, tensor dtype, safetensors metadata) as each distillation publishes its LoRA.
DISTILLATION_LORAS = [
    ("sdxl_lightning_4step_lora.safetensors", torch.float16, None),
    ("Hyper-SDXL-8steps-CFG-lora.safetensors", torch.float32, {"format": "pt"}),
    ("lcm-lora-sdxl/pytorch_lora_weights.safetensors", torch.float16, None),
    ("TCD-SDXL-LoRA/pytorch_lora_weights.safetensors", torch.float16, None),
    ("dmd2_sdxl_4step_lora_fp16.safetensors", torch.float16, None),
]
LORA_RANK, LORA_ALPHA = 16, 8.0
# The modules every distillation LoRA targets, as module path suffixes (788 of them in SDXL).
LORA_TARGETS = ("attn1.to_q", "attn1.to_k", "attn1.to_v", "attn1.to_out.0", "attn2.to_q", "attn2.to_k", "attn2.to_v",
                "attn2.to_out.0", "ff.net.0.proj", "ff.net.2", "proj_in", "proj_out", "time_emb_proj", "conv1", "conv2",
                "conv_shortcut", "downsamplers.0.conv", "upsamplers.0.conv")
# fuse_lora's weights recorded for these (a linear, a 3×3 conv, a 1×1 conv, the time projection).
LORA_RECORDS = [("unet", "down_blocks.1.attentions.0.transformer_blocks.0.attn2.to_k"),
                ("unet", "mid_block.resnets.0.conv1"), ("unet", "up_blocks.0.resnets.0.conv_shortcut"),
                ("unet", "up_blocks.1.resnets.1.time_emb_proj")]
STYLE_LORAS = [("workflow/lora-kohya-ldm.safetensors", 0.8), ("workflow/lora-peft.safetensors", 0.5)]


def case(name, sampler, guidance, seed, steps=None, **settings):
    c = dict(name=name, prompt=PROMPT, seed=seed, sampler=sampler, guidance_scale=guidance, width=64, height=64,
             **settings)
    c["steps"] = len(c["timesteps"]) if "timesteps" in c else steps
    return c


CASES = [
    # SDXL-Lightning: Euler, trailing, guidance 0; its one-step UNet predicts the sample.
    case("lightning_4", "euler", 0.0, 1, 4, timestep_spacing="trailing"),
    case("lightning_1_x0", "euler", 0.0, 2, 1, timestep_spacing="trailing", prediction_type="sample"),
    # Hyper-SD: DDIM or TCD, trailing; its CFG-preserving LoRAs keep guidance.
    case("hyper_ddim_8", "ddim", 0.0, 3, 8, timestep_spacing="trailing"),
    case("hyper_tcd_cfg", "tcd", 5.0, 4, 4, eta=1.0),
    # LCM-LoRA: LCMScheduler, guidance 1 (no negative pass) and above.
    case("lcm_4", "lcm", 1.0, 5, 4),
    case("lcm_cfg_2", "lcm", 2.0, 6, 2),
    # TCD: gamma 0.3 (the step's default) and 0.
    case("tcd_4", "tcd", 0.0, 7, 4, eta=0.3),
    case("tcd_deterministic", "tcd", 0.0, 8, 6, eta=0.0),
    # SDXL-Turbo: its folder's Euler-ancestral with trailing, guidance 0.
    case("turbo_2", "euler_a", 0.0, 9, 2, timestep_spacing="trailing"),
    # DMD2: LCMScheduler over its own four timesteps.
    case("dmd2_4", "lcm", 0.0, 10, timesteps=[999, 749, 499, 249]),
    case("dpmpp_custom", "dpmpp_2m", 1.0, 11, timesteps=[999, 850, 600, 300, 100]),
    # The depth ControlNet over few steps: its start and end count them.
    case("control_lightning", "euler", 0.0, 12, 4, timestep_spacing="trailing",
         control=dict(CONTROL, start=0.25, end=0.75)),
    case("control_lcm", "lcm", 1.0, 13, 4, control=dict(CONTROL, start=0.0, end=0.5)),
    case("control_tcd_cfg", "tcd", 3.0, 14, 4, eta=0.3, control=dict(CONTROL, start=0.0, end=1.0)),
    case("control_dmd2", "lcm", 0.0, 15, timesteps=[999, 749, 499, 249], control=dict(CONTROL, start=0.0, end=1.0)),
    # img2img from the render, trailing: the last int(steps * strength) steps run.
    case("img2img_lightning", "euler", 0.0, 16, 4, timestep_spacing="trailing", init="init-64.png", strength=0.5),
    case("img2img_lcm", "lcm", 1.0, 17, 4, init="init-64.png", strength=0.75),
    case("img2img_tcd", "tcd", 0.0, 18, 8, eta=0.3, init="init-64.png", strength=0.5),
    case("img2img_hyper_ddim", "ddim", 0.0, 19, 4, timestep_spacing="trailing", init="init-64.png", strength=0.6),
    case("img2img_control_lightning", "euler", 0.0, 20, 4, timestep_spacing="trailing", init="init-64.png",
         strength=0.75, control=dict(CONTROL, start=0.0, end=1.0)),
    # A UNet swapped in (Lightning's and DMD2's UNet files), in each stored layout.
    *[case(f"unet_{f.split('.')[0][5:]}_{f.split('.')[1]}", "euler", 0.0, 21, 4, timestep_spacing="trailing", unet=f)
      for f in UNET_FILES],
    case("unet_dmd2_control", "lcm", 0.0, 22, timesteps=[999, 749, 499, 249], unet=UNET_FILES[0],
         control=dict(CONTROL, start=0.0, end=1.0)),
    # Each distillation LoRA under its recipe; DMD2's beside the style LoRAs, with the ControlNet.
    case("lora_lightning", "euler", 0.0, 23, 4, timestep_spacing="trailing",
         loras=[("few_step/" + DISTILLATION_LORAS[0][0], 1.0)]),
    case("lora_hyper_cfg", "ddim", 5.0, 24, 8, timestep_spacing="trailing",
         loras=[("few_step/" + DISTILLATION_LORAS[1][0], 1.0)]),
    case("lora_lcm", "lcm", 1.0, 25, 4, loras=[("few_step/" + DISTILLATION_LORAS[2][0], 1.0)]),
    case("lora_tcd", "tcd", 0.0, 26, 4, eta=0.3, loras=[("few_step/" + DISTILLATION_LORAS[3][0], 1.0)]),
    case("lora_dmd2_styles_control", "lcm", 0.0, 27, timesteps=[999, 749, 499, 249],
         loras=[("few_step/" + DISTILLATION_LORAS[4][0], 1.0), *STYLE_LORAS],
         control=dict(CONTROL, start=0.0, end=1.0)),
]


def distilled_unet(base_folder):
    """The base UNet's architecture with every weight re-drawn (float16-exact)."""
    unet = UNet2DConditionModel.from_pretrained(base_folder / "unet", torch_dtype=torch.float32)
    redraw(unet, torch.Generator().manual_seed(sum(map(ord, "distilled unet"))))
    return unet


def write_unet_files(unet, out):
    state = {k: v.half().contiguous() for k, v in unet.state_dict().items()}
    save_file(state, out / UNET_FILES[0])
    original = single_file_state(unet, torch.float16)
    prefix = "model.diffusion_model."
    save_file({k[len(prefix):]: v.contiguous() for k, v in original.items()}, out / UNET_FILES[1])
    torch.save(state, out / UNET_FILES[2])


def load_swapped_unet(base_folder, out, name):
    """As the model cards: from the base UNet's config, then load_state_dict of the file."""
    unet = UNet2DConditionModel.from_config(UNet2DConditionModel.load_config(base_folder / "unet"))
    path = out / name
    if name.endswith(".bin"):
        state = torch.load(path, weights_only=True)
    elif name == UNET_FILES[1]:
        # diffusers reads the original layout through its single-file converter.
        from diffusers.loaders.single_file_utils import convert_ldm_unet_checkpoint
        stored = load_file(path)
        state = convert_ldm_unet_checkpoint({"model.diffusion_model." + k: v for k, v in stored.items()},
                                            config=dict(unet.config))
    else:
        state = load_file(path)
    unet.load_state_dict({k: v.float() for k, v in state.items()})
    unet.set_attn_processor(wf.AttnProcessor2_0())
    return unet.eval()


def distillation_lora(pipe, stem):
    """Every target module of the UNet: kohya names over diffusers paths, rank LORA_RANK, alpha LORA_ALPHA."""
    gen = wf.gen_for(stem)
    state, spec = {}, []
    for path, m in pipe.unet.named_modules():
        if not path.endswith(LORA_TARGETS) or not hasattr(m, "weight"):
            continue
        key = "lora_unet_" + path.replace(".", "_")
        w = wf.base_weight(pipe, "unet", path)
        down, up = wf.lora_pair(gen, w, LORA_RANK, LORA_ALPHA / LORA_RANK)
        state |= {f"{key}.lora_down.weight": down, f"{key}.lora_up.weight": up, f"{key}.alpha": torch.tensor(LORA_ALPHA)}
        spec.append(dict(key=key, component="unet", module=path, rank=LORA_RANK, alpha=LORA_ALPHA,
                         scale=LORA_ALPHA / LORA_RANK, down=list(down.shape), up=list(up.shape)))
    return state, spec


def write_loras(base_folder, out, tensors):
    """The distillation LoRAs, each held to diffusers' load_lora_weights and fuse_lora."""
    records = {}
    for name, dtype, metadata in DISTILLATION_LORAS:
        pipe = wf.load_base(base_folder)
        state, spec = distillation_lora(pipe, name)
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        save_file({k: v.to(dtype).contiguous() for k, v in state.items()}, path, metadata=metadata)
        n = wf.check_lora(pipe, path, spec, "check")
        pipe.unload_lora_weights()
        stem = name.replace("/", "_").removesuffix(".safetensors")
        wf.FUSE_RECORDS[stem] = LORA_RECORDS
        fused, worst = wf.lora_fuse_records(pipe, path, spec, "check", tensors, stem)
        print(f"{name}: {len(state)} tensors, {n} modules applied by diffusers with scale alpha/r; fuse_lora matches "
              f"W + s(alpha/r)BA to {worst:.1e}")
        records[stem] = dict(file=name, tensors=len(state), modules=spec, metadata=metadata,
                             fused_strength=wf.FUSE_STRENGTH, fused_records=fused)
    return records


def pipeline(c, base_folder, workflow, out):
    base = wf.load_base(base_folder)
    parts = dict(base.components)
    if "unet" in c:
        parts["unet"] = load_swapped_unet(base_folder, out, c["unet"])
    if "control" in c:
        net = ControlNetModel.from_pretrained(workflow / c["control"]["model"], variant="fp16", torch_dtype=torch.float32)
        cls = diffusers.StableDiffusionXLControlNetImg2ImgPipeline if "init" in c else StableDiffusionXLControlNetPipeline
        pipe = cls(**parts, controlnet=net, add_watermarker=False)
    elif "init" in c:
        pipe = StableDiffusionXLImg2ImgPipeline(**parts, add_watermarker=False)
    else:
        pipe = StableDiffusionXLPipeline(**parts, add_watermarker=False)
    if "loras" in c:
        names = [f"l{i}" for i in range(len(c["loras"]))]
        for name, (file, _) in zip(names, c["loras"]):
            pipe.load_lora_weights(str(out.parent / file), adapter_name=name)
        pipe.set_adapters(names, adapter_weights=[s for _, s in c["loras"]])
    overrides = {k: c[k] for k in ("timestep_spacing", "prediction_type") if k in c}
    pipe.scheduler = SCHEDULERS[c["sampler"]].from_config(base.scheduler.config, **overrides)
    pipe.set_progress_bar_config(disable=True)
    return pipe


def run_case(c, base_folder, workflow, compat, out):
    pipe = pipeline(c, base_folder, workflow, out)
    kwargs = dict(prompt=c["prompt"], guidance_scale=c["guidance_scale"], width=c["width"], height=c["height"])
    kwargs |= dict(timesteps=c["timesteps"]) if "timesteps" in c else dict(num_inference_steps=c["steps"])
    if "eta" in c:
        kwargs["eta"] = c["eta"]
    if "init" in c:
        kwargs |= dict(image=wf.open_rgb(compat / c["init"]), strength=c["strength"])
    if "control" in c:
        cc = c["control"]
        image = wf.open_rgb(workflow / cc["image"])
        kwargs |= dict(controlnet_conditioning_scale=cc["scale"], control_guidance_start=cc["start"],
                       control_guidance_end=cc["end"])
        kwargs |= dict(control_image=image) if "init" in c else dict(image=image)
    run = lambda kind: pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(c["seed"]), output_type=kind)
    latents = run("latent").images
    timesteps = [float(t) for t in pipe.scheduler.timesteps]
    pil = run("pil").images[0]
    return latents, torch.from_numpy(np.array(pil)).float(), timesteps


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="tests/fixtures/few_step")
    ap.add_argument("--pipeline", default="tests/fixtures/pipeline/tiny-sdxl")
    ap.add_argument("--workflow", default="tests/fixtures/workflow")
    ap.add_argument("--compat", default="tests/fixtures/compat")
    args = ap.parse_args()
    out, base_folder = pathlib.Path(args.out), pathlib.Path(args.pipeline)
    workflow, compat = pathlib.Path(args.workflow), pathlib.Path(args.compat)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_grad_enabled(False)
    torch.set_num_threads(2)
    write_unet_files(distilled_unet(base_folder), out)
    tensors, cases = {}, []
    loras = write_loras(base_folder, out, tensors)
    for c in CASES:
        latents, image, timesteps = run_case(c, base_folder, workflow, compat, out)
        wf.check_sane(c["name"], latents)
        p = f"gen.{c['name']}."
        tensors[p + "latents"], tensors[p + "image_u8"] = latents.contiguous(), image.contiguous()
        # `timesteps` in the records of tests/fixtures/pipeline is diffusers' output: the input is named apart.
        entry = {("custom_timesteps" if k == "timesteps" else k): v for k, v in c.items()}
        cases.append(dict(entry, negative_prompt=None, diffusers_timesteps=timesteps,
                          tensors=dict(latents=p + "latents", image_u8=p + "image_u8")))
        print(f"{c['name']:28s} timesteps {timesteps}; latents std {latents.std():.3f} mean {latents.mean():+.3f}")
    swapped = [tensors[f"gen.{c['name']}.latents"] for c in cases if c["name"].startswith("unet_") and
               "control" not in c]
    assert all(torch.equal(swapped[0], s) for s in swapped), "the three UNet files differ"
    lightning = tensors["gen.lightning_4.latents"]
    assert not torch.equal(lightning, swapped[0]), "the swapped UNet changed nothing"
    save_file(tensors, out / "records.safetensors")
    meta = dict(
        description=f"diffusers (float32, CPU) on the tiny SDXL of {base_folder}; written by "
                    "tools/make_few_step_fixtures.py. Cases follow tests/fixtures/compat/records.json's conventions, "
                    "with the schedule options under vkdiff's names (timestep_spacing, prediction_type, "
                    "custom_timesteps for --timesteps, eta), `unet` the file swapped in and `loras` [file under tests/fixtures, strength]; "
                    "diffusers_timesteps are the scheduler's after the run. `loras` lists the distillation LoRAs as "
                    "tests/fixtures/workflow/records.json lists its LoRAs.",
        versions=dict(torch=torch.__version__, diffusers=diffusers.__version__, transformers=transformers.__version__,
                      safetensors=safetensors.__version__),
        cases=cases, loras=loras)
    (out / "records.json").write_text(json.dumps(meta, indent=1) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
