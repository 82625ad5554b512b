#!/usr/bin/env python3
"""fp8 checkpoints as torch writes them, and what torch and diffusers read from them.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU), diffusers 0.42.1,
safetensors 0.8.0. Setup as for tools/make_unet_fixtures.py, whose `heads` fixture this reads:
  /tmp/ref/bin/python tools/make_fp8_fixtures.py [--out tests/fixtures/fp8]

Writes:
  float8.safetensors: every byte as `float8_e4m3fn` and as `float8_e5m2` (safetensors' F8_E4M3
      and F8_E5M2), beside torch's own float32 of each;
  heads_e4m3.safetensors: the `heads` UNet in the original single-file names with every weight
      of two or more dimensions cast to float8_e4m3fn by torch (as fp8 SDXL checkpoints ship),
      norms and biases left in bfloat16;
  io.safetensors: diffusers' float32 output on the `heads` inputs (`out_plain`) for those weights,
      widened back to float32 by torch.
"""
import argparse
import pathlib
import sys

import torch
from diffusers import UNet2DConditionModel
from diffusers.models.attention_processor import AttnProcessor2_0
from safetensors.torch import load_file, save_file

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from make_unet_fixtures import run, single_file_state  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="tests/fixtures/fp8")
    ap.add_argument("--heads", default="tests/fixtures/unet/heads")
    args = ap.parse_args()
    out, heads = pathlib.Path(args.out), pathlib.Path(args.heads)
    out.mkdir(parents=True, exist_ok=True)

    every_byte = torch.arange(256, dtype=torch.uint8)
    codes = {}
    for name, dtype in (("e4m3", torch.float8_e4m3fn), ("e5m2", torch.float8_e5m2)):
        codes[name] = every_byte.clone().view(dtype)
        codes[f"{name}_f32"] = codes[name].float()
    save_file(codes, out / "float8.safetensors")

    unet = UNet2DConditionModel.from_pretrained(heads / "unet", torch_dtype=torch.float32).eval()
    unet.set_attn_processor(AttnProcessor2_0())
    with torch.no_grad():
        for p in unet.parameters():
            if p.dim() >= 2:
                p.copy_(p.to(torch.float8_e4m3fn).float())
    state = single_file_state(unet, torch.float32)
    state = {k: v.to(torch.float8_e4m3fn if v.dim() >= 2 else torch.bfloat16) for k, v in state.items()}
    save_file(state, out / "heads_e4m3.safetensors")

    io = load_file(heads / "io.safetensors")
    names = ("sample", "timestep", "encoder_hidden_states", "text_embeds", "time_ids")
    inputs = {k: io[k] for k in names}
    save_file({"out_plain": run(unet, inputs).contiguous()}, out / "io.safetensors")
    fp8 = sum(v.numel() for v in state.values() if v.dtype == torch.float8_e4m3fn)
    print("fp8 values:", fp8, "of", sum(v.numel() for v in state.values()))


if __name__ == "__main__":
    main()
