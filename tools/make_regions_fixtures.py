#!/usr/bin/env python3
"""A prompt per category and a strength per region on the tiny SDXL, written from ComfyUI's semantics
with diffusers' models and schedulers: the reference latents of pipeline/tests/regions.rs.

What it follows (ComfyUI, comfy/samplers.py and comfy_extras/nodes_differential_diffusion.py):
- Masked conditioning, `get_area_and_mult` and `calc_cond_batch`: each conditioning's mask is
  resized to the latent grid with `torch.nn.functional.interpolate(mode="bilinear")` and becomes its
  `mult`; the positive prediction is `sum(output * mult) / (1e-37 + sum(mult))` over the positive
  conditionings (`out_conds += output * mult`, `out_counts += mult`, counts starting at 1e-37), the
  negative's the same with its one unmasked conditioning; then `cfg_function`:
  `uncond + (cond - uncond) * cfg`. Here the scene's prompt is masked to the pixels of no prompted
  category and each category's prompt to its pixels; every mask is feathered first.
- Differential denoising, `DifferentialDiffusion.forward` as `denoise_mask_function` of
  `KSamplerX0Inpaint`: at a step of timestep t, threshold = (t - t_to) / (t_from - t_to) with t_from
  the first step's timestep and t_to that of sigma_min (0); a pixel is denoised where its strength
  map is >= threshold (within 1e-9, as rounding leaves a feathered field of one strength), elsewhere its input is the init latent noised to this step
  (`scale_latent_inpaint`: latent + noise * sigma, here the scheduler's own add_noise) and its
  denoised output the init latent (`out * denoise_mask + latent_image * latent_mask`), which for an
  epsilon model is the model output replaced by that same noise. The strength map is the strengths
  divided by the largest strength given, and the schedule runs as img2img at that largest strength
  (ComfyUI's KSampler `denoise`), so equal strengths everywhere are plain img2img.
- Feathering (vkdiff's definition, as ComfyUI users blur their masks by hand): a separable Gaussian
  of standard deviation PX/2 over taps -PX..PX, edges clamped, horizontal then vertical, in float64.

Scene: tests/fixtures/scenes/folders/orchard-a (160x128; instances.png and categories.json give each
pixel's category: 1 apple, 2 leaf, 3 branch; shaded.png is the render img2img starts from). Writes
tests/fixtures/workflow/regions.json (the cases, with the masks' definitions) and regions.safetensors
(float32 latents, NCHW, before VAE scaling).

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
transformers 5.23.0, numpy 2.4.6, Pillow 13.0.0.
  /tmp/ref/bin/python tools/make_regions_fixtures.py"""
import json
import math
import pathlib
import sys

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image
from safetensors.torch import save_file

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import make_workflow_fixtures as w  # noqa: E402
from diffusers import ControlNetModel, LCMScheduler  # noqa: E402
from diffusers.image_processor import VaeImageProcessor  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "tests/fixtures/workflow"
BASE = ROOT / "tests/fixtures/pipeline/tiny-sdxl"
SCENE = ROOT / "tests/fixtures/scenes/folders/orchard-a"
SAMPLERS = dict(w.SAMPLERS, lcm=LCMScheduler)

CASES = [
    dict(name="regions_cfg_controlnet", prompt="an orchard at dusk", seed=41, steps=4, sampler="euler",
         guidance_scale=5.0, feather=3, region_prompts={"apple": "a shiny red apple", "leaf": "a green leaf"},
         control=dict(model="controlnet", image="control.png", scale=0.7, start=0.0, end=1.0)),
    dict(name="strengths_img2img", prompt="an orchard at dusk", seed=42, steps=5, sampler="euler",
         guidance_scale=5.0, feather=3, init_strength=0.75, strengths={"apple": 0.3, "leaf": 0.55},
         background_strength=0.9, control=dict(model="controlnet", image="control.png", scale=0.7, start=0.0,
                                               end=1.0)),
    dict(name="regions_strengths_lcm", prompt="an orchard in the rain", seed=43, steps=4, sampler="lcm",
         guidance_scale=1.0, feather=2, region_prompts={"apple": "a golden apple"}, init_strength=0.8,
         strengths={"apple": 0.4}, background_strength=1.0),
    dict(name="regions_ip_adapter", prompt="an orchard at noon", seed=44, steps=4, sampler="euler",
         guidance_scale=5.0, feather=2, region_prompts={"apple": "a shiny red apple", "leaf": "a green leaf"},
         ip=dict(adapter="ip-adapter_tiny.safetensors", images=["style-1.png"], scale=0.6)),
]


def scene_categories():
    """Each pixel's category id (0 background) and the categories' names."""
    meta = json.loads((SCENE / "categories.json").read_text())
    ids = np.asarray(Image.open(SCENE / "instances.png")).astype(np.int64)
    lut = np.zeros(ids.max() + 1, np.int64)
    for instance, category in meta["instances"].items():
        lut[int(instance)] = category
    return lut[ids], {c["name"]: c["id"] for c in meta["categories"]}


def feather(mask, px):
    if px == 0:
        return mask
    sigma = px / 2.0
    # math.exp and a left-to-right sum, as a plain loop in any language computes them.
    raw = [math.exp(-k * k / (2 * sigma * sigma)) for k in range(-px, px + 1)]
    total = sum(raw)
    taps = [t / total for t in raw]
    h, wd = mask.shape
    out = np.zeros_like(mask)
    for j, k in enumerate(range(-px, px + 1)):
        out += taps[j] * mask[:, np.clip(np.arange(wd) + k, 0, wd - 1)]
    mask, out = out, np.zeros_like(mask)
    for j, k in enumerate(range(-px, px + 1)):
        out += taps[j] * mask[np.clip(np.arange(h) + k, 0, h - 1), :]
    return out


def bilinear(mask, h, wd):
    """PyTorch's bilinear resize (align_corners=False), written out; checked against F.interpolate."""
    def axis(n_in, n_out):
        src = np.maximum((np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5, 0.0)
        lo = np.floor(src).astype(np.int64)
        hi = np.minimum(lo + 1, n_in - 1)
        return lo, hi, src - lo
    (y0, y1, fy), (x0, x1, fx) = axis(mask.shape[0], h), axis(mask.shape[1], wd)
    top = mask[y0][:, x0] * (1 - fx) + mask[y0][:, x1] * fx
    bottom = mask[y1][:, x0] * (1 - fx) + mask[y1][:, x1] * fx
    out = top * (1 - fy)[:, None] + bottom * fy[:, None]
    torch_out = F.interpolate(torch.from_numpy(mask)[None, None], size=(h, wd), mode="bilinear")[0, 0].numpy()
    assert np.abs(out - torch_out).max() < 1e-12, "the written-out resize differs from F.interpolate"
    return out


def region_masks(case, cats, names, lh, lw):
    """The scene prompt's mask then each region prompt's, feathered, on the latent grid."""
    prompted = [names[n] for n in case.get("region_prompts", {})]
    own = [(cats == c).astype(np.float64) for c in prompted]
    base = 1.0 - sum(own) if own else np.ones(cats.shape)
    return [bilinear(feather(m, case["feather"]), lh, lw) for m in [base] + own]


def strength_map(case, cats, names, lh, lw):
    """Per pixel: its category's strength, the background's, else --init-strength; over the largest."""
    default = case["init_strength"]
    s = np.full(cats.shape, default, np.float64)
    for name, value in case.get("strengths", {}).items():
        s[cats == names[name]] = value
    if "background_strength" in case:
        s[cats == 0] = case["background_strength"]
    largest = max([default, case.get("background_strength", default)] + list(case.get("strengths", {}).values()))
    return bilinear(feather(s, case["feather"]), lh, lw) / largest, largest


def encode(pipe, prompt, guided):
    embeds, negative, pooled, negative_pooled = pipe.encode_prompt(prompt, device="cpu", num_images_per_prompt=1,
                                                                   do_classifier_free_guidance=guided)
    return embeds, negative, pooled, negative_pooled


def run(case, cats, names, controlnet):
    pipe = w.load_base(BASE)
    scheduler = SAMPLERS[case["sampler"]].from_config(pipe.scheduler.config)
    height, width = cats.shape
    lh, lw = height // 8, width // 8
    guided = case["guidance_scale"] > 1.0
    embeds, negative, pooled, negative_pooled = encode(pipe, case["prompt"], guided)
    rows_e, rows_p = ([negative] if guided else []) + [embeds], ([negative_pooled] if guided else []) + [pooled]
    for prompt in case.get("region_prompts", {}).values():
        e, _, p, _ = encode(pipe, prompt, False)
        rows_e.append(e)
        rows_p.append(p)
    context, text_embeds = torch.cat(rows_e), torch.cat(rows_p)
    rows = context.shape[0]
    time_ids = torch.tensor([[height, width, 0, 0, height, width]], dtype=torch.float32).repeat(rows, 1)
    image_embeds = None
    if "ip" in case:
        # Every region's row sees the image embeddings the positive row sees.
        w.load_ip(pipe, OUT, case["ip"]["adapter"])
        pipe.set_ip_adapter_scale(case["ip"]["scale"])
        images = [[Image.open(OUT / f).convert("RGB") for f in case["ip"]["images"]]]
        embeds = pipe.prepare_ip_adapter_image_embeds(images, None, "cpu", 1, guided)[0]
        positive = embeds[-1:]
        image_embeds = [torch.cat([embeds] + [positive] * (rows - embeds.shape[0]))]
    masks = [torch.from_numpy(m).float()[None, None] for m in region_masks(case, cats, names, lh, lw)]

    generator = torch.Generator("cpu").manual_seed(case["seed"])
    scheduler.set_timesteps(case["steps"])
    timesteps = scheduler.timesteps
    strengths = None
    if "init_strength" in case:
        rel, largest = strength_map(case, cats, names, lh, lw)
        strengths = torch.from_numpy(rel)
        run_steps = min(int(case["steps"] * largest), case["steps"])
        first = case["steps"] - run_steps
        timesteps = timesteps[first:]
        scheduler.set_begin_index(first)
        image = VaeImageProcessor(vae_scale_factor=8).preprocess(Image.open(SCENE / "shaded.png").convert("RGB"),
                                                                 height=height, width=width)
        dist = pipe.vae.encode(image).latent_dist
        encoded = dict(mean=dist.mean, std=dist.std)
        init = dist.sample(generator) * pipe.vae.config.scaling_factor
        noise = torch.randn(init.shape, generator=generator)
        latents = scheduler.add_noise(init, noise, timesteps[:1])
    else:
        encoded = None
        latents = torch.randn((1, 4, lh, lw), generator=generator) * scheduler.init_noise_sigma
    hint = None
    if controlnet is not None:
        c = case["control"]
        processor = VaeImageProcessor(vae_scale_factor=8, do_convert_rgb=True, do_normalize=False)
        hint = processor.preprocess(Image.open(OUT / c["image"]).convert("RGB"), height=height, width=width)
        hint = hint.repeat(rows, 1, 1, 1)
    t_from = float(timesteps[0])
    for i, t in enumerate(timesteps):
        keep = None
        if strengths is not None:
            threshold = float(t) / t_from
            # A strength within 1e-9 of the threshold reaches it (a feathered field of one strength is 1
            # only up to rounding).
            keep = torch.from_numpy((strengths.numpy() + 1e-9 >= threshold).astype(np.float32))[None, None]
            if keep.min() < 1:
                latents = latents * keep + scheduler.add_noise(init, noise, t[None]) * (1 - keep)
        x = scheduler.scale_model_input(torch.cat([latents] * rows), t)
        added = dict(text_embeds=text_embeds, time_ids=time_ids)
        if image_embeds is not None:
            added["image_embeds"] = image_embeds
        residuals = {}
        if controlnet is not None:
            n = len(scheduler.timesteps)
            on = not (i / n < c["start"] or (i + 1) / n > c["end"])
            down, mid = controlnet(x, t, encoder_hidden_states=context, controlnet_cond=hint,
                                   conditioning_scale=c["scale"] * float(on), added_cond_kwargs=added,
                                   return_dict=False)
            residuals = dict(down_block_additional_residuals=down, mid_block_additional_residual=mid)
        out = pipe.unet(x, t, encoder_hidden_states=context, added_cond_kwargs=added, return_dict=False,
                        **residuals)[0]
        conds = out[1:] if guided else out
        total, counts = torch.zeros_like(conds[:1]), torch.ones_like(masks[0]) * 1e-37
        for output, mult in zip(conds, masks):
            total = total + output[None] * mult
            counts = counts + mult
        cond = total / counts
        prediction = out[:1] + (cond - out[:1]) * case["guidance_scale"] if guided else cond
        if keep is not None and keep.min() < 1:
            prediction = prediction * keep + noise * (1 - keep)
        latents = scheduler.step(prediction, t, latents, generator=generator, return_dict=False)[0]
    return latents, encoded


def main():
    torch.set_grad_enabled(False)
    torch.set_num_threads(2)
    cats, names = scene_categories()
    controlnet = ControlNetModel.from_pretrained(OUT / "controlnet", variant="fp16", torch_dtype=torch.float32)
    tensors, cases = {}, []
    for c in CASES:
        latents, encoded = run(c, cats, names, controlnet if "control" in c else None)
        names_of = dict(latents=f"regions.{c['name']}.latents")
        tensors[names_of["latents"]] = latents.contiguous()
        # The VAE encoder's distribution of the render, so that a test can start from diffusers' own
        # (the encoder is held to diffusers on its own, at 1e-4).
        for key, value in (encoded or {}).items():
            names_of[f"init_{key}"] = f"regions.{c['name']}.init_{key}"
            tensors[names_of[f"init_{key}"]] = value.contiguous()
        cases.append(dict(c, width=cats.shape[1], height=cats.shape[0], tensors=names_of))
        print(f"{c['name']}: latents std {latents.std():.3f}")
    save_file(tensors, OUT / "regions.safetensors")
    import diffusers
    import transformers
    meta = dict(description="A prompt per category (ComfyUI's masked conditioning) and a strength per region "
                            "(ComfyUI's DifferentialDiffusion) with diffusers' tiny SDXL, float32 on the CPU.",
                scene="tests/fixtures/scenes/folders/orchard-a",
                versions=dict(torch=torch.__version__, diffusers=diffusers.__version__,
                              transformers=transformers.__version__, numpy=np.__version__),
                cases=cases)
    (OUT / "regions.json").write_text(json.dumps(meta, indent=1) + "\n")
    print("wrote", OUT / "regions.json")


main()
