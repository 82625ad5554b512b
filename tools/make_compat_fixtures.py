#!/usr/bin/env python3
"""diffusers' outputs for what `vkdiff gen` takes from users' habits, on the tiny SDXL of
tests/fixtures/pipeline/tiny-sdxl with the IP-Adapter of tests/fixtures/workflow:

  - IP-Adapter per-block scales: pipe.set_ip_adapter_scale(<dict>) (InstantStyle's style-only form and a mix of
    whole blocks, single attentions and the mid block), each case with the `--ip-scale` flags that mean the same;
  - SDXL size micro-conditioning: original_size, crops_coords_top_left, target_size;
  - img2img: StableDiffusionXLImg2ImgPipeline with every sampler, and StableDiffusionXLControlNetImg2ImgPipeline with
    an init image of another size (resized by the pipeline);
  - A1111-syntax weighted and long prompts as diffusers' long-prompt-weighting SDXL pipeline reads them
    (examples/community/lpw_stable_diffusion_xl.py of the diffusers repository, loaded from --lpw; it is not in the
    pip package): parse_prompt_attention on a corpus, and generations from get_weighted_text_embeddings_sdxl's
    embeddings through StableDiffusionXLPipeline;
  - a CLIP vision encoder of 40 channels over 4 heads (head size 10, off vkdiff's vec4 kernel layout): its
    image_embeds and hidden_states[-2] from transformers;
  - a LoRA as diffusers' training scripts save it under transformers 5: PEFT adapters added to the UNet and both
    text encoders, saved with StableDiffusionXLPipeline.save_lora_weights(get_peft_model_state_dict(...),
    *_lora_adapter_metadata=...), which writes CLIP-L keys without the `text_model.` level
    (`text_encoder.encoder.layers.N...`), since transformers 5's CLIPTextModel has none; and the same factors as
    ComfyUI's LoRA save node writes them (`diffusion_model.<original UNet path>.lora_up.weight`,
    `text_encoders.clip_l.transformer.text_model...`, `.alpha` per module), which diffusers does not load: merged, it
    must give what the diffusers file gives.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1, transformers
5.23.0, peft 0.21.2, safetensors 0.8.0, pillow 13.0.0.
Setup and rerun (the tiny pipeline and the workflow fixtures must exist; they are loaded, not regenerated):
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch torchvision diffusers transformers peft safetensors pillow
  git clone https://github.com/huggingface/diffusers /tmp/diffusers   (for examples/community/lpw_stable_diffusion_xl.py;
      the committed fixtures used the file at commit 58eb52c080)
  /tmp/ref/bin/python tools/make_compat_fixtures.py --lpw /tmp/diffusers/examples/community/lpw_stable_diffusion_xl.py
      [--out tests/fixtures/compat]

Writes under --out: records.json (every case's settings, as records.json of tests/fixtures/workflow), records.safetensors
(float32), lora-peft-transformers5.safetensors, lora-comfyui.safetensors, init-64.png and init-80x72.png (RGB init images),
image_encoder_head10/ (transformers CLIPVisionModelWithProjection, float16 on disk).
"""
import argparse
import importlib.util
import json
import pathlib
import sys

import numpy as np
import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import make_workflow_fixtures as wf  # noqa: E402

import diffusers  # noqa: E402
import peft  # noqa: E402
import safetensors  # noqa: E402
import transformers  # noqa: E402
from peft import LoraConfig  # noqa: E402
from peft.utils import get_peft_model_state_dict  # noqa: E402
from safetensors.torch import load_file, save_file  # noqa: E402
from diffusers import (  # noqa: E402
    ControlNetModel, StableDiffusionXLControlNetImg2ImgPipeline, StableDiffusionXLImg2ImgPipeline,
    StableDiffusionXLPipeline,
)
from PIL import Image  # noqa: E402

IP = dict(adapter="ip-adapter_tiny.safetensors", images=["style-1.png"])
CASES = [
    # InstantStyle's style-only adapter on a UNet of two attentions per up block: up_blocks.0.attentions.1.
    dict(name="ip_style_only", prompt="a wooden cabin in a snowy forest", seed=21, steps=4, sampler="euler",
         width=64, height=64, ip=dict(IP, scale={"up": {"block_0": [0.0, 1.0]}}), ip_scale_flags=["up.0.1=1"]),
    dict(name="ip_blocks", prompt="a wooden cabin in a snowy forest", seed=21, steps=4, sampler="euler",
         width=64, height=64,
         ip=dict(IP, scale={"down": {"block_1": 0.5}, "mid": 0.3, "up": {"block_0": [0.0, 0.9], "block_1": 0.8}}),
         ip_scale_flags=["down.1=0.5", "mid=0.3", "up.0.1=0.9", "up.1=0.8"]),
    # diffusers' (height, width) and (top, left) order.
    dict(name="size_conditioning", prompt="a lighthouse on a cliff at dusk", seed=5, steps=4, sampler="euler_a",
         width=64, height=96, original_size=(192, 128), crops_coords_top_left=(32, 16), target_size=(96, 64)),
    # img2img: diffusers runs the last int(steps * strength) steps.
    *[dict(name=f"img2img_{sampler}", prompt="a red barn in a green field", seed=8, steps=steps, sampler=sampler,
           width=64, height=64, init="init-64.png", strength=strength)
      for sampler, steps, strength in (("euler", 4, 0.5), ("euler_a", 4, 0.75), ("dpmpp_2m", 5, 0.6), ("ddim", 4, 0.5))],
    dict(name="img2img_controlnet_resized", prompt="a stone bridge over a river", seed=13, steps=4, sampler="euler",
         width=64, height=64, init="init-80x72.png", strength=0.7,
         control=dict(model="controlnet", image="control.png", scale=0.7, start=0.0, end=1.0)),
]

# Weighted prompts: (name, prompt, negative (None = absent), seed, sampler).
WEIGHTED = [
    ("weighted_short", "a (red:1.4) barn in a [green] field, ((detailed)), \\(photo\\)", "blurry, (low quality:1.3)", 31, "euler"),
    ("weighted_long", "a (cozy wooden cabin:1.2) in a snowy pine forest at dusk, warm light glowing from the small square windows, "
     "smoke curling from a stone chimney, [tall] pine trees heavy with fresh snow on every side, a frozen lake in the "
     "foreground reflecting the last (orange and purple:0.8) light of the sky, footprints leading to the red front door, "
     "a wooden sled leaning against the porch, stacked firewood under the eaves, soft falling snowflakes, (((cinematic))) "
     "wide angle photograph, high detail, sharp focus", None, 32, "euler_a"),
]
PARSE_CORPUS = [
    "normal text", "an (important) word", "(unbalanced", "\\(literal\\]", "(unnecessary)(parens)",
    "a (((house:1.3)) [on] a (hill:0.5), sun, (((sky))).", "[[faded]] and ((bold:1.5))", "(a:-0.5) (b:+2) (c:.5)",
    "colon: not a weight (x:1.2", "unclosed [square (and:1.1) round", "]stray) closers(", "a\\b \\ c", "",
    "emoji 🍄 (mushrooms:1.25), 蘑菇",
]
LORA_STEM = "lora-peft-transformers5"
# (component, target modules as peft matches them (suffixes), r, lora_alpha)
PEFT_ADAPTERS = [
    ("unet", ["attn1.to_k", "attn2.to_v", "proj_in", "resnets.0.conv1", "time_emb_proj"], 4, 8.0),
    ("text_encoder", ["self_attn.q_proj", "self_attn.out_proj", "mlp.fc2"], 4, 2.0),
    ("text_encoder_2", ["self_attn.k_proj", "mlp.fc1"], 2, 4.0),
]
FUSE_RECORDS = [("unet", "down_blocks.1.attentions.0.transformer_blocks.0.attn1.to_k"),
                ("unet", "up_blocks.0.resnets.0.conv1"),
                ("text_encoder", "text_model.encoder.layers.1.self_attn.q_proj"),
                ("text_encoder_2", "text_model.encoder.layers.0.mlp.fc1")]


SAMPLERS = dict(wf.SAMPLERS, ddim=diffusers.DDIMScheduler)


def make_init_images(out):
    for (w, h), phase in (((64, 64), 0.7), ((80, 72), 1.9)):
        y, x = np.mgrid[0:h, 0:w].astype(np.float64)
        rgb = np.stack([0.5 + 0.5 * np.sin(x / w * 6 + phase), 0.5 + 0.5 * np.cos(y / h * 4 - phase),
                        ((x // 8 + y // 8) % 2) * 0.6 + 0.2], -1)
        name = "init-64.png" if w == h else f"init-{w}x{h}.png"
        Image.fromarray((rgb * 255).round().astype(np.uint8), "RGB").save(out / name)


def img2img_pipeline(c, base_folder, workflow):
    base = wf.load_base(base_folder)
    if "control" in c:
        net = ControlNetModel.from_pretrained(workflow / c["control"]["model"], variant="fp16", torch_dtype=torch.float32)
        pipe = StableDiffusionXLControlNetImg2ImgPipeline(**base.components, controlnet=net, add_watermarker=False)
    else:
        pipe = StableDiffusionXLImg2ImgPipeline(**base.components, add_watermarker=False)
    pipe.set_progress_bar_config(disable=True)
    return pipe


def run_case(c, base_folder, workflow, out):
    if "init" in c:
        pipe = img2img_pipeline(c, base_folder, workflow)
        kwargs = dict(image=wf.open_rgb(out / c["init"]), strength=c["strength"])
        if "control" in c:
            cc = c["control"]
            kwargs |= dict(control_image=wf.open_rgb(workflow / cc["image"]), controlnet_conditioning_scale=cc["scale"],
                           control_guidance_start=cc["start"], control_guidance_end=cc["end"], width=c["width"],
                           height=c["height"])
    else:
        pipe = wf.load_base(base_folder)
        kwargs = dict(width=c["width"], height=c["height"])
    pipe.scheduler = SAMPLERS[c["sampler"]].from_config(pipe.scheduler.config)
    kwargs |= dict(prompt=c["prompt"], num_inference_steps=c["steps"], guidance_scale=wf.GUIDANCE)
    for key in ("original_size", "crops_coords_top_left", "target_size"):
        if key in c:
            kwargs[key] = c[key]
    if "ip" in c:
        wf.load_ip(pipe, workflow, c["ip"]["adapter"])
        pipe.set_ip_adapter_scale(c["ip"]["scale"])
        kwargs["ip_adapter_image"] = [[wf.open_rgb(workflow / f) for f in c["ip"]["images"]]]
    latents = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(c["seed"]), output_type="latent").images
    pil = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(c["seed"]), output_type="pil").images[0]
    return latents, torch.from_numpy(np.array(pil)).float()


def ip_scales_in_effect(base_folder, workflow, scale):
    """Each IP processor's scale after set_ip_adapter_scale(scale), by processor name: what the flags must give."""
    pipe = wf.load_base(base_folder)
    wf.load_ip(pipe, workflow, IP["adapter"])
    pipe.set_ip_adapter_scale(scale)
    return {name.removesuffix(".processor"): p.scale[0] for name, p in pipe.unet.attn_processors.items()
            if hasattr(p, "scale")}


def build_transformers5_lora(base_folder, path):
    """PEFT adapters on every component, weights drawn like the workflow LoRAs, saved as diffusers saves them."""
    pipe = wf.load_base(base_folder)
    gen = wf.gen_for(LORA_STEM)
    layers, metadata = {}, {}
    for comp, targets, r, alpha in PEFT_ADAPTERS:
        model = getattr(pipe, comp)
        config = LoraConfig(r=r, lora_alpha=alpha, target_modules=targets, init_lora_weights=True)
        model.add_adapter(config)
        for name, m in model.named_modules():
            if hasattr(m, "lora_A") and "default" in m.lora_A:
                down, up = wf.lora_pair(gen, m.base_layer.weight, r, alpha / r)
                m.lora_A["default"].weight.copy_(down.reshape(m.lora_A["default"].weight.shape))
                m.lora_B["default"].weight.copy_(up.reshape(m.lora_B["default"].weight.shape))
        layers[comp] = get_peft_model_state_dict(model)
        metadata[comp] = model.peft_config["default"].to_dict()
    StableDiffusionXLPipeline.save_lora_weights(
        path.parent, weight_name=path.name, unet_lora_layers=layers["unet"],
        text_encoder_lora_layers=layers["text_encoder"], text_encoder_2_lora_layers=layers["text_encoder_2"],
        unet_lora_adapter_metadata=metadata["unet"], text_encoder_lora_adapter_metadata=metadata["text_encoder"],
        text_encoder_2_lora_adapter_metadata=metadata["text_encoder_2"])
    keys = sorted(load_file(path))
    assert any(k.startswith("text_encoder.encoder.layers.") for k in keys), "expected transformers 5's CLIP-L keys"
    return keys


HEAD10_ENCODER = dict(wf.IMAGE_ENCODER_CONFIG, hidden_size=40, num_attention_heads=4, intermediate_size=96,
                      num_hidden_layers=2, projection_dim=24)


def head10_encoder_records(out, tensors):
    """A vision encoder with head size 10, saved in float16 (exact values), and transformers' outputs."""
    from transformers import CLIPVisionConfig, CLIPVisionModelWithProjection
    folder = out / "image_encoder_head10"
    model = CLIPVisionModelWithProjection(CLIPVisionConfig(**HEAD10_ENCODER)).eval()
    wf.redraw(model, wf.gen_for("image_encoder_head10"))
    model.to(torch.float16).save_pretrained(folder, safe_serialization=True)
    model = CLIPVisionModelWithProjection.from_pretrained(folder, dtype=torch.float32).eval()
    size = HEAD10_ENCODER["image_size"]
    pixels = torch.randn((2, 3, size, size), generator=wf.gen_for("head10-pixels"))
    o = model(pixel_values=pixels, output_hidden_states=True)
    tensors["head10.pixel_values"] = pixels.contiguous()
    tensors["head10.image_embeds"] = o.image_embeds.contiguous()
    tensors["head10.hidden_m2"] = o.hidden_states[-2].contiguous()
    return dict(folder=folder.name, tensors=dict(pixel_values="head10.pixel_values", image_embeds="head10.image_embeds",
                                                 hidden_m2="head10.hidden_m2"))


def write_comfyui_copy(base_folder, spec, source, path):
    """The factors of `source` under ComfyUI's key names, each module with its alpha."""
    from make_unet_fixtures import reference_ldm_names
    config = json.loads((base_folder / "unet" / "config.json").read_text())
    to_ldm = {d.removesuffix(".weight"): o.removesuffix(".weight") for o, d in reference_ldm_names(config).items()}
    factors = load_file(source)
    out = {}
    for m in spec:
        comp, module = m["component"], m["module"]
        if comp == "unet":
            key = f"diffusion_model.{to_ldm[module]}"
        else:
            key = f"text_encoders.{'clip_l' if comp == 'text_encoder' else 'clip_g'}.transformer.{module}"
        out[f"{key}.lora_down.weight"] = factors[f"{m['key']}.lora_A.weight"]
        out[f"{key}.lora_up.weight"] = factors[f"{m['key']}.lora_B.weight"]
        out[f"{key}.alpha"] = torch.tensor(m["alpha"], dtype=torch.float32)
    save_file(out, path)
    return len(out)


def lora_spec(base_folder, path):
    """What diffusers applies from the file: every wrapped module with its scale (checked by wf.check_lora)."""
    pipe = wf.load_base(base_folder)
    pipe.load_lora_weights(str(path), adapter_name="probe")
    spec = []
    for (comp, module), m in sorted(wf.lora_modules(pipe).items()):
        if "probe" not in m.lora_A:
            continue
        r = m.lora_A["probe"].weight.shape[0]
        stored = module.removeprefix("text_model.") if comp == "text_encoder" else module
        spec.append(dict(key=f"{comp}.{stored}", component=comp, module=module, rank=r,
                         alpha=m.scaling["probe"] * r, scale=m.scaling["probe"],
                         down=list(m.lora_A["probe"].weight.shape), up=list(m.lora_B["probe"].weight.shape)))
    return spec


def load_lpw(path):
    spec = importlib.util.spec_from_file_location("lpw_stable_diffusion_xl", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def weighted_records(lpw, base_folder, tensors):
    """parse_prompt_attention on the corpus; each weighted case's embeddings and its generation from them."""
    parses = {text: [[t, w] for t, w in lpw.parse_prompt_attention(text)] for text in PARSE_CORPUS}
    cases = []
    for name, prompt, negative, seed, sampler in WEIGHTED:
        pipe = wf.load_base(base_folder)
        pipe.scheduler = SAMPLERS[sampler].from_config(pipe.scheduler.config)
        pe, npe, ppe, nppe = lpw.get_weighted_text_embeddings_sdxl(pipe, prompt=prompt, neg_prompt=negative or "",
                                                                   device="cpu")
        kwargs = dict(prompt_embeds=pe, negative_prompt_embeds=npe, pooled_prompt_embeds=ppe,
                      negative_pooled_prompt_embeds=nppe, num_inference_steps=4, guidance_scale=wf.GUIDANCE,
                      width=64, height=64)
        latents = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(seed), output_type="latent").images
        pil = pipe(**kwargs, generator=torch.Generator("cpu").manual_seed(seed), output_type="pil").images[0]
        p = f"gen.{name}."
        tensors[p + "latents"] = latents.contiguous()
        tensors[p + "image_u8"] = torch.from_numpy(np.array(pil)).float().contiguous()
        tensors[p + "context"] = torch.cat([npe, pe]).contiguous()
        tensors[p + "pooled"] = torch.cat([nppe, ppe]).contiguous()
        tokens = pe.shape[1]
        print(f"{name:20s} {tokens} tokens; latents std {latents.std():.3f}")
        cases.append(dict(name=name, prompt=prompt, negative_prompt=negative, prompt_syntax="weighted", seed=seed, steps=4,
                          sampler=sampler, width=64, height=64, guidance_scale=wf.GUIDANCE, tokens=tokens,
                          tensors=dict(latents=p + "latents", image_u8=p + "image_u8", context=p + "context",
                                       pooled=p + "pooled")))
    return parses, cases


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="tests/fixtures/compat")
    ap.add_argument("--pipeline", default="tests/fixtures/pipeline/tiny-sdxl")
    ap.add_argument("--workflow", default="tests/fixtures/workflow")
    ap.add_argument("--lpw", required=True, help="examples/community/lpw_stable_diffusion_xl.py of the diffusers repository")
    args = ap.parse_args()
    out, base_folder, workflow = pathlib.Path(args.out), pathlib.Path(args.pipeline), pathlib.Path(args.workflow)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_grad_enabled(False)
    torch.set_num_threads(2)
    tensors = {}
    meta = dict(
        description=f"diffusers (float32, CPU) on the tiny SDXL of {base_folder}; written by "
                    "tools/make_compat_fixtures.py. Cases follow tests/fixtures/workflow/records.json's conventions; "
                    "sizes in diffusers' (height, width) order; ip.scale is set_ip_adapter_scale's argument and "
                    "ip_scale_flags the --ip-scale values meaning the same; ip_scales the scale diffusers then holds "
                    "per cross-attention processor.",
        versions=dict(torch=torch.__version__, diffusers=diffusers.__version__, transformers=transformers.__version__,
                      peft=peft.__version__, safetensors=safetensors.__version__),
        cases=[])
    make_init_images(out)
    for c in CASES:
        latents, image = run_case(c, base_folder, workflow, out)
        wf.check_sane(c["name"], latents)
        # The feature must show: without it (IP scale 1 everywhere, default sizes) the latents differ.
        plain = {k: v for k, v in c.items() if k not in ("original_size", "crops_coords_top_left", "target_size")}
        if "ip" in c:
            plain["ip"] = dict(c["ip"], scale=1.0)
        if "init" in c:
            plain["strength"] = 1.0
        moved = ((latents - run_case(plain, base_folder, workflow, out)[0]).norm() / latents.norm()).item()
        assert moved > 1e-2, f"{c['name']}: the feature moves the latents by only {moved:.1e}"
        p = f"gen.{c['name']}."
        tensors[p + "latents"], tensors[p + "image_u8"] = latents.contiguous(), image.contiguous()
        entry = dict(c, guidance_scale=wf.GUIDANCE, negative_prompt=None,
                     tensors=dict(latents=p + "latents", image_u8=p + "image_u8"))
        if "ip" in c:
            entry["ip_scales"] = ip_scales_in_effect(base_folder, workflow, c["ip"]["scale"])
        meta["cases"].append(entry)
        print(f"{c['name']:20s} latents std {latents.std():.3f} mean {latents.mean():+.3f}; {moved:.2f} (relative) "
              "away from the same case without the feature")

    meta["image_encoder_head10"] = head10_encoder_records(out, tensors)
    meta["parse_prompt_attention"], weighted = weighted_records(load_lpw(args.lpw), base_folder, tensors)
    meta["cases"].extend(weighted)
    path = out / f"{LORA_STEM}.safetensors"
    keys = build_transformers5_lora(base_folder, path)
    spec = lora_spec(base_folder, path)
    pipe = wf.load_base(base_folder)
    n = wf.check_lora(pipe, path, spec, "check")
    pipe.unload_lora_weights()
    wf.FUSE_RECORDS[LORA_STEM] = FUSE_RECORDS
    fused, worst = wf.lora_fuse_records(pipe, path, spec, "check", tensors, LORA_STEM)
    print(f"{LORA_STEM}: {len(keys)} tensors, {n} modules applied by diffusers; fuse_lora matches W + s(alpha/r)BA "
          f"to {worst:.1e}")
    comfy = write_comfyui_copy(base_folder, spec, path, out / "lora-comfyui.safetensors")
    print(f"lora-comfyui: {comfy} tensors, the same factors under ComfyUI's names")
    meta["lora_comfyui"] = dict(file="lora-comfyui.safetensors", same_factors_as=path.name)
    meta["loras"] = {LORA_STEM: dict(file=path.name, tensors=len(keys), modules=spec, fused_strength=wf.FUSE_STRENGTH,
                                     fused_records=fused, keys_sample=keys[:3] + [k for k in keys if "text_encoder." in k][:2])}
    save_file({k: v.float().contiguous() for k, v in tensors.items()}, out / "records.safetensors")
    (out / "records.json").write_text(json.dumps(meta, indent=1, ensure_ascii=False, allow_nan=False) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
