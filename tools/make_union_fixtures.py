#!/usr/bin/env python3
"""A tiny ControlNet-Union (diffusers ControlNetUnionModel, as xinsir/controlnet-union-sdxl-1.0 and its
ProMax file) for the tiny SDXL of tests/fixtures/pipeline/tiny-sdxl, and diffusers' residuals for it, for
networks/tests/networks/controlnet_union.rs.

The base part is tests/fixtures/workflow/controlnet/ (ControlNetModel.from_unet of the tiny SDXL UNet with
every parameter redrawn non-zero, tools/make_workflow_fixtures.py); ControlNetUnionModel is built with its
config plus num_control_type and num_trans_channel = num_proj_channel = 32 (the first block's width: the
fused token is mean_hw(hint) + task_embedding), loads those weights, and gets seeded non-zero union extras
(task_embedding, transformer_layes.0, spatial_ch_projs, control_add_embedding), all float16-representable so
the float32 reference uses exactly the stored values. diffusers' from_unet cannot set the union widths.

Writes under tests/fixtures/workflow:
  controlnet-union/: config.json + diffusion_pytorch_model.safetensors (float16), num_control_type 6.
  controlnet-union-promax.safetensors: the same base with its own extras for num_control_type 8, one
      float16 file in diffusers names, no config (as xinsir's diffusion_pytorch_model_promax.safetensors).
  union.safetensors + union.json: per case the inputs (sample, timestep, encoder_hidden_states, text_embeds,
      time_ids, control images as control_image_processor gives them) and the float32 residuals (down.0-8,
      mid) of ControlNetUnionModel.forward; union.json lists each case's modes, scales and what each part
      of the union changes.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
safetensors 0.8.0, numpy 2.4.6, Pillow 13.0.0.
  /tmp/ref/bin/python tools/make_union_fixtures.py"""
import json
import pathlib
import shutil
import sys

import numpy as np
import torch
from PIL import Image
from safetensors.torch import load_file, save_file

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_unet_fixtures import representable_everywhere as R  # noqa: E402

import diffusers  # noqa: E402
from diffusers import ControlNetUnionModel  # noqa: E402
from diffusers.image_processor import VaeImageProcessor  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = ROOT / "tests/fixtures/workflow"
BASE = OUT / "controlnet"
UNION_KEYS = ("task_embedding", "transformer_layes.", "spatial_ch_projs.", "control_add_embedding.")

# name, model, batch rows (all carry the same images), [(image, mode, scale)], height, width, timestep.
CASES = [
    ("one", "base", 1, [("control.png", 1, 0.7)], 64, 64, 601.0),
    ("two", "base", 1, [("control.png", 1, 0.8), ("control-edges.png", 3, 0.5)], 64, 64, 421.0),
    ("promax", "promax", 1, [("control-edges.png", 5, 1.0)], 64, 96, 801.0),
    ("batch2", "base", 2, [("control.png", 3, 1.0)], 64, 64, 241.0),
]


def build(types, seed):
    config = {k: v for k, v in json.loads((BASE / "config.json").read_text()).items() if not k.startswith("_")}
    assert config.pop("mid_block_type") == "UNetMidBlock2DCrossAttn"  # the union's only mid block
    c0 = config["block_out_channels"][0]
    cn = ControlNetUnionModel(**config, num_control_type=types, num_trans_channel=c0, num_proj_channel=c0)
    cn.eval()
    base = load_file(BASE / "diffusion_pytorch_model.fp16.safetensors")
    missing, unexpected = cn.load_state_dict({k: v.float() for k, v in base.items()}, strict=False)
    assert not unexpected and all(k.startswith(UNION_KEYS) for k in missing), (missing, unexpected)
    assert len(missing) == 19, missing
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name in missing:
            p = cn.get_parameter(name)
            if name == "task_embedding":
                v = 0.5 * torch.randn(p.shape, generator=gen)
            elif p.ndim == 1:
                v = (1.0 if name.endswith("weight") else 0.0) + 0.1 * torch.randn(p.shape, generator=gen)
            else:
                v = torch.randn(p.shape, generator=gen) / p[0].numel() ** 0.5
            p.copy_(R(v))
    return cn


def control_image(name, height, width):
    processor = VaeImageProcessor(vae_scale_factor=8, do_convert_rgb=True, do_normalize=False)
    return processor.preprocess(Image.open(OUT / name).convert("RGB"), height=height, width=width).float()


def forward(cn, inputs, conds):
    types = cn.config.num_control_type
    control_type = torch.zeros(types).scatter_(0, torch.tensor([m for _, m, _ in conds]), 1).reshape(1, -1)
    rows = inputs["sample"].shape[0]
    down, mid = cn(inputs["sample"], inputs["timestep"], encoder_hidden_states=inputs["encoder_hidden_states"],
                   controlnet_cond=[inputs[f"image.{j}"] for j in range(len(conds))],
                   control_type=control_type.repeat(rows, 1), control_type_idx=[m for _, m, _ in conds],
                   conditioning_scale=[s for _, _, s in conds],
                   added_cond_kwargs=dict(text_embeds=inputs["text_embeds"], time_ids=inputs["time_ids"]),
                   return_dict=False)
    return list(down) + [mid]


def moved(a, b):
    num = sum(((x - y) ** 2).sum() for x, y in zip(a, b)) ** 0.5
    return (num / sum((y ** 2).sum() for y in b) ** 0.5).item()


def main():
    torch.set_grad_enabled(False)
    torch.set_num_threads(2)
    nets = dict(base=build(6, 601), promax=build(8, 802))
    folder = OUT / "controlnet-union"
    if folder.exists():
        shutil.rmtree(folder)
    fp16 = {k: v.to(torch.float16) for k, v in nets["base"].state_dict().items()}
    nets["base"].save_pretrained(folder, safe_serialization=True)
    save_file({k: v.contiguous() for k, v in fp16.items()}, folder / "diffusion_pytorch_model.safetensors")
    promax = {k: v.to(torch.float16).contiguous() for k, v in nets["promax"].state_dict().items()}
    save_file(promax, OUT / "controlnet-union-promax.safetensors")
    back = ControlNetUnionModel.from_pretrained(folder, torch_dtype=torch.float32).state_dict()
    assert all(torch.equal(back[k], v) for k, v in nets["base"].state_dict().items()), "reload differs"

    config = json.loads((BASE / "config.json").read_text())
    gen = torch.Generator().manual_seed(4242)
    tensors, cases = {}, []
    for name, model, rows, conds, height, width, t in CASES:
        cn = nets[model]
        inputs = dict(
            sample=torch.randn(rows, 4, height // 8, width // 8, generator=gen),
            timestep=torch.full((rows,), t),
            encoder_hidden_states=torch.randn(rows, 12, config["cross_attention_dim"], generator=gen),
            text_embeds=torch.randn(rows, config["projection_class_embeddings_input_dim"] - 6 * 256, generator=gen),
            time_ids=torch.tensor([[height, width, 0, 0, height, width]], dtype=torch.float32).repeat(rows, 1))
        for j, (image, _, _) in enumerate(conds):
            inputs[f"image.{j}"] = control_image(image, height, width).repeat(rows, 1, 1, 1)
        out = forward(cn, inputs, conds)
        # Each union part matters: another mode, no spatial_ch_projs, no control embedding.
        other = [(i, (m + 1) % cn.config.num_control_type, s) for i, m, s in conds]
        saved = cn.spatial_ch_projs.weight.clone(), cn.spatial_ch_projs.bias.clone()
        cn.spatial_ch_projs.weight.zero_(), cn.spatial_ch_projs.bias.zero_()
        no_alpha = forward(cn, inputs, conds)
        cn.spatial_ch_projs.weight.copy_(saved[0]), cn.spatial_ch_projs.bias.copy_(saved[1])
        saved = cn.control_add_embedding.linear_2.weight.clone(), cn.control_add_embedding.linear_2.bias.clone()
        cn.control_add_embedding.linear_2.weight.zero_(), cn.control_add_embedding.linear_2.bias.zero_()
        no_control_emb = forward(cn, inputs, conds)
        cn.control_add_embedding.linear_2.weight.copy_(saved[0])
        cn.control_add_embedding.linear_2.bias.copy_(saved[1])
        effects = dict(other_mode=moved(forward(cn, inputs, other), out), no_alpha=moved(no_alpha, out),
                       no_control_embedding=moved(no_control_emb, out))
        assert min(effects.values()) > 1e-3, (name, effects)
        for k, v in inputs.items():
            tensors[f"{name}.input.{k}"] = v.contiguous()
        for k, v in enumerate(out):
            tensors[f"{name}.{'mid' if k == len(out) - 1 else f'down.{k}'}"] = v.contiguous()
        cases.append(dict(name=name, model=model, rows=rows, height=height, width=width, timestep=t,
                          conditions=[dict(image=i, mode=m, scale=s) for i, m, s in conds],
                          residual_stds=[round(v.std().item(), 4) for v in out], effects=effects))
        print(f"{name}: residual stds {cases[-1]['residual_stds']}; effects {effects}")
    save_file(tensors, OUT / "union.safetensors")
    meta = dict(
        description="diffusers ControlNetUnionModel.forward in float32 on the CPU: controlnet_cond = the images, "
                    "control_type = multi-hot of the modes (one row per batch row), control_type_idx = the modes, "
                    "conditioning_scale = the scales; residuals as returned (one condition: x scale; several: "
                    "unscaled). Images: VaeImageProcessor(do_convert_rgb=True, do_normalize=False).preprocess "
                    "at (height, width), repeated over the rows. effects: relative L2 change of the residuals "
                    "with the next mode, with spatial_ch_projs zeroed, with control_add_embedding.linear_2 zeroed.",
        versions=dict(torch=torch.__version__, diffusers=diffusers.__version__, numpy=np.__version__),
        cases=cases)
    (OUT / "union.json").write_text(json.dumps(meta, indent=1) + "\n")
    print("wrote", OUT / "union.json")


main()
