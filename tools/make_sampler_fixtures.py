#!/usr/bin/env python3
"""torch.randn streams and diffusers scheduler runs, for vkdiff-pipeline's rng and sampler tests.

Versions used to write the committed fixtures: Python 3.11, torch 2.15.0 (CPU, x86-64 with AVX2),
diffusers 0.42.1, numpy 2.4, safetensors 0.8.0. The `add_noise` tensors were added later (2026-11-28,
the same versions, on a 2-core AMD EPYC) beside the others as first written: a rerun on another CPU
gives the loops' tensors within an ulp or so (torch's MKL), inside the tests' tolerance. Setup and rerun:
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install torch diffusers safetensors
  /tmp/ref/bin/python tools/make_sampler_fixtures.py [--out tests/fixtures/pipeline]

Writes samplers.safetensors (every tensor float32) and samplers.json, which lists the cases:
  rng: torch.randn(n, generator=torch.Generator("cpu").manual_seed(seed)) as `rng/<seed>/<n>`;
  rng_sequences: several randn calls on one generator, concatenated, as `rngseq/<seed>/<n1>_<n2>`
      (pins the stream continuation and the cached normal of the <16-element path);
  samplers: `XScheduler.from_config(config, use_karras_sigmas=karras)` then `set_timesteps(steps)`,
      with `<case>/timesteps`, `<case>/sigmas` (Euler, Euler-ancestral, DPM-Solver only),
      `<case>/init_noise_sigma`, and a denoising loop on a (1,4,8,8) latent:
          g = manual_seed(seed); latents = randn(shape, generator=g) * init_noise_sigma
          per t: x_in = scale_model_input(latents, t); eps = model(x_in, t);
                 latents = step(eps, t, latents, generator=g)
      whose result is `<case>/final` (and `<case>/latents`, every step stacked, for 7-step cases).
      `model` is a synthetic ε-model built from IEEE-exact operations only, so a replica can match
      it bit for bit: eps = x_in / (1 + |x_in|) * 0.5 + t / 5000 (float32).
      Cases of 2 steps or more have `<case>/add_noise`: img2img's start, a fresh scheduler after
      set_timesteps(steps) and set_begin_index(steps // 2), add_noise(x0, noise, timesteps[begin])
      where g = manual_seed(seed + 1); x0 = randn(shape, generator=g); noise = randn(shape, g).
      Cases with "timesteps" call set_timesteps(timesteps=...) (their "steps" is the count); cases
      with "eta" pass it to TCDScheduler.step as the pipelines do (without it, step's default 0.3).
      LCM and TCD cases (added 2026-12-04, diffusers 0.42.1, torch 2.15.0, the same 2-core AMD EPYC)
      cover step counts 1 to 50, custom schedules, v/sample prediction, original_inference_steps,
      clip_sample and gamma 0 to 1; Euler and DPM++ 2M take custom schedules and prediction "sample"
      (SDXL-Lightning's one-step UNet).
      Cases with "error": true are settings vkdiff refuses (no tensors): Karras sigmas for DDIM,
      LCM and TCD (unsupported by diffusers) and for Euler-ancestral (diffusers 0.42.1 silently
      ignores use_karras_sigmas there; checked below), DDIM with a negative timestep, custom
      timesteps where the class takes none, and the schedules diffusers raises on;
      "diffusers_refuses" says whether diffusers raises too.
"""
import argparse
import json
import pathlib

import numpy as np
import torch
from diffusers import (DDIMScheduler, DPMSolverMultistepScheduler, EulerAncestralDiscreteScheduler,
                       EulerDiscreteScheduler, LCMScheduler, TCDScheduler)
from safetensors.torch import save_file

# stabilityai/stable-diffusion-xl-base-1.0 scheduler/scheduler_config.json
SDXL = {
    "_class_name": "EulerDiscreteScheduler", "_diffusers_version": "0.19.0.dev0",
    "beta_end": 0.012, "beta_schedule": "scaled_linear", "beta_start": 0.00085, "clip_sample": False,
    "interpolation_type": "linear", "num_train_timesteps": 1000, "prediction_type": "epsilon",
    "sample_max_value": 1.0, "set_alpha_to_one": False, "skip_prk_steps": True, "steps_offset": 1,
    "timestep_spacing": "leading", "trained_betas": None, "use_karras_sigmas": False,
}
CLASSES = {
    "euler": EulerDiscreteScheduler, "euler_a": EulerAncestralDiscreteScheduler,
    "dpmpp_2m": DPMSolverMultistepScheduler, "ddim": DDIMScheduler, "lcm": LCMScheduler, "tcd": TCDScheduler,
}
# The few-step recipes' custom schedules (diffusers' `timesteps=`): DMD2's, Hyper-SD's one-step
# UNet's, and one off the distillation schedule.
CUSTOM_TIMESTEPS = [[999, 749, 499, 249], [800], [999, 850, 700, 500, 300, 120, 10]]
RNG_SEEDS = [0, 42, 2**32 + 5, 2**63 + 7, 123456789]
RNG_SIZES = [1, 3, 15, 16, 17, 33, 100, 1000]
RNG_SEQUENCES = [(0, [3, 5]), (42, [20, 7]), (7, [3, 5, 16, 1])]
SHAPE = (1, 4, 8, 8)


def model(x_in, t):
    return x_in / (1 + x_in.abs()) * 0.5 + t / 5000


def sampler_cases():
    cases = []

    def add(name, kind, karras=False, steps=7, error=False, timesteps=None, eta=None, **overrides):
        config = dict(SDXL)
        for key, value in overrides.items():
            if value is None:
                config.pop(key, None)
            else:
                config[key] = value
        case = dict(name=name, kind=kind, karras=karras, steps=len(timesteps) if timesteps else steps,
                    config=config, error=error)
        if timesteps is not None:
            case["timesteps"] = timesteps
        if eta is not None:
            case["eta"] = eta
        cases.append(case)

    for kind in ["euler", "euler_a", "dpmpp_2m", "ddim"]:
        for karras in [False, True]:
            if karras and kind in ("euler_a", "ddim"):
                add(f"{kind}/karras", kind, karras=True, error=True)
                continue
            for spacing in ["leading", "trailing", "linspace"]:
                for steps in [1, 4, 7, 30]:
                    name = f"{kind}/{'karras' if karras else 'plain'}/{spacing}/{steps}"
                    add(name, kind, karras, steps, timestep_spacing=spacing)
    for kind in ["euler", "euler_a", "dpmpp_2m", "ddim"]:
        add(f"{kind}/v_prediction", kind, prediction_type="v_prediction")
        add(f"{kind}/linear_betas", kind, beta_schedule="linear", beta_start=0.0001, beta_end=0.02,
            timestep_spacing="linspace", steps_offset=0)
        # 1000 / 61 is inexact: numpy's arange yields 62 trailing timesteps, the last being -1.
        add(f"{kind}/trailing_61", kind, steps=61, timestep_spacing="trailing", error=kind == "ddim")
    add("euler/karras/v_prediction", "euler", karras=True, prediction_type="v_prediction")
    add("euler/karras/sigma_min_final", "euler", karras=True, final_sigmas_type="sigma_min")
    add("euler/karras/sigma_range", "euler", karras=True, sigma_min=0.1, sigma_max=10.0)
    add("dpmpp_2m/karras/sigma_range", "dpmpp_2m", karras=True, sigma_min=0.1, sigma_max=10.0)
    add("dpmpp_2m/karras/sigma_min_final", "dpmpp_2m", karras=True, final_sigmas_type="sigma_min")
    add("dpmpp_2m/sigma_min_final/30", "dpmpp_2m", steps=30, final_sigmas_type="sigma_min")
    add("dpmpp_2m/sigma_min_final/no_lower_order_final", "dpmpp_2m", final_sigmas_type="sigma_min",
        lower_order_final=False)
    add("dpmpp_2m/euler_at_final/30", "dpmpp_2m", steps=30, final_sigmas_type="sigma_min",
        euler_at_final=True)
    # DDIMScheduler's own defaults: clip_sample and set_alpha_to_one both true.
    add("ddim/class_defaults", "ddim", clip_sample=None, set_alpha_to_one=None)
    # Added 2026-12-04, after the first cases so that those keep their seeds.
    for kind in ["lcm", "tcd"]:
        # Their schedules ignore timestep_spacing: one spacing suffices.
        for steps in [1, 2, 4, 7, 8, 50]:
            add(f"{kind}/{steps}", kind, steps=steps)
        for timesteps in CUSTOM_TIMESTEPS:
            add(f"{kind}/custom/{len(timesteps)}", kind, timesteps=timesteps)
        add(f"{kind}/v_prediction", kind, prediction_type="v_prediction")
        add(f"{kind}/sample", kind, prediction_type="sample")
        add(f"{kind}/original_inference_steps_20", kind, steps=4, original_inference_steps=20)
        add(f"{kind}/class_defaults", kind, set_alpha_to_one=None, steps_offset=None, timestep_spacing=None)
        add(f"{kind}/too_many_steps", kind, steps=51, error=True)
        add(f"{kind}/karras", kind, karras=True, error=True)
    add("lcm/clip_sample", "lcm", clip_sample=True, clip_sample_range=0.5)
    for eta in [0.0, 0.5, 1.0]:
        add(f"tcd/eta_{eta}", "tcd", steps=4, eta=eta)
        add(f"tcd/custom/eta_{eta}", "tcd", timesteps=CUSTOM_TIMESTEPS[0], eta=eta)
    add("tcd/eta_1.5", "tcd", eta=1.5, error=True)
    for kind in ["euler", "dpmpp_2m"]:
        for timesteps in CUSTOM_TIMESTEPS:
            for spacing in ["leading", "trailing"]:  # the spacing still sets Euler's init_noise_sigma
                add(f"{kind}/custom/{len(timesteps)}/{spacing}", kind, timesteps=timesteps, timestep_spacing=spacing)
        add(f"{kind}/custom/karras", kind, karras=True, timesteps=CUSTOM_TIMESTEPS[0], error=True)
        add(f"{kind}/sample/trailing", kind, steps=4, prediction_type="sample", timestep_spacing="trailing")
    add("euler/sample/trailing/1", "euler", steps=1, prediction_type="sample", timestep_spacing="trailing")
    add("ddim/sample/trailing", "ddim", steps=4, prediction_type="sample", timestep_spacing="trailing")
    for kind in ["euler_a", "ddim"]:
        add(f"{kind}/custom", kind, timesteps=CUSTOM_TIMESTEPS[0], error=True)
    add("euler_a/sample", "euler_a", prediction_type="sample", error=True)
    add("euler/custom/ascending", "euler", timesteps=[249, 499], error=True)
    add("lcm/custom/past_training", "lcm", timesteps=[1000, 500], error=True)

    return cases


def set_timesteps(sched, case):
    if "timesteps" in case:
        sched.set_timesteps(timesteps=case["timesteps"])
    else:
        sched.set_timesteps(case["steps"])


def step_kwargs(case):
    """TCD's gamma as the pipelines pass it (`eta`); TCDScheduler.step's own default is 0.3."""
    return {"eta": case["eta"]} if "eta" in case else {}


def check_refused(case):
    """The cases marked as errors that diffusers itself refuses do raise there."""
    sched = CLASSES[case["kind"]].from_config(case["config"], use_karras_sigmas=case["karras"])
    try:
        set_timesteps(sched, case)
        if case["kind"] == "euler_a":  # prediction_type="sample": raised at the first step
            sched.step(torch.zeros(SHAPE), sched.timesteps[0], torch.zeros(SHAPE))
        if "eta" in case:
            sched.step(torch.zeros(SHAPE), sched.timesteps[0], torch.zeros(SHAPE), eta=case["eta"])
    except (ValueError, TypeError, NotImplementedError, AssertionError):
        return True
    return False


def run_case(case, seed, tensors):
    cls = CLASSES[case["kind"]]
    sched = cls.from_config(case["config"], use_karras_sigmas=case["karras"])
    set_timesteps(sched, case)
    name = case["name"]
    tensors[f"{name}/timesteps"] = sched.timesteps.to(torch.float32)
    if hasattr(sched, "sigmas"):
        tensors[f"{name}/sigmas"] = sched.sigmas.to(torch.float32)
    tensors[f"{name}/init_noise_sigma"] = torch.tensor([float(sched.init_noise_sigma)], dtype=torch.float32)
    g = torch.Generator("cpu").manual_seed(seed)
    latents = torch.randn(SHAPE, generator=g, dtype=torch.float32) * sched.init_noise_sigma
    per_step = []
    for t in sched.timesteps:
        x_in = sched.scale_model_input(latents, t)
        eps = model(x_in, t)
        assert eps.dtype == torch.float32
        latents = sched.step(eps, t, latents, generator=g, **step_kwargs(case)).prev_sample
        per_step.append(latents)
    tensors[f"{name}/final"] = latents.contiguous()
    if case["steps"] == 7:
        tensors[f"{name}/latents"] = torch.stack(per_step).contiguous()
    # img2img's start: a fresh scheduler begun at step `steps // 2`, as the pipelines'
    # get_timesteps sets it, noising x0 to that step's timestep.
    if case["steps"] >= 2:
        start = sched.__class__.from_config(case["config"], use_karras_sigmas=case["karras"])
        set_timesteps(start, case)
        begin = case["steps"] // 2
        if hasattr(start, "set_begin_index"):  # DDIM noises by the timestep alone
            start.set_begin_index(begin)
        g = torch.Generator("cpu").manual_seed(seed + 1)
        x0, noise = (torch.randn(SHAPE, generator=g, dtype=torch.float32) for _ in range(2))
        tensors[f"{name}/add_noise"] = start.add_noise(x0, noise, start.timesteps[begin:begin + 1]).contiguous()


def check_ancestral_ignores_karras():
    sigmas = []
    for karras in [False, True]:
        sched = EulerAncestralDiscreteScheduler.from_config(SDXL, use_karras_sigmas=karras)
        sched.set_timesteps(30)
        sigmas.append(sched.sigmas)
    assert torch.equal(*sigmas), "diffusers now honours use_karras_sigmas for Euler-ancestral"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="tests/fixtures/pipeline")
    out = pathlib.Path(parser.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)
    check_ancestral_ignores_karras()
    tensors, listing = {}, {"rng": [], "rng_sequences": [], "samplers": []}
    for seed in RNG_SEEDS:
        for n in RNG_SIZES + ([65536] if seed == 0 else []):
            name = f"rng/{seed}/{n}"
            g = torch.Generator("cpu").manual_seed(seed)
            tensors[name] = torch.randn(n, generator=g, dtype=torch.float32)
            listing["rng"].append(dict(name=name, seed=seed, n=n))
    for seed, sizes in RNG_SEQUENCES:
        name = f"rngseq/{seed}/{'_'.join(map(str, sizes))}"
        g = torch.Generator("cpu").manual_seed(seed)
        tensors[name] = torch.cat([torch.randn(n, generator=g, dtype=torch.float32) for n in sizes])
        listing["rng_sequences"].append(dict(name=name, seed=seed, sizes=sizes))
    for seed, case in enumerate(sampler_cases()):
        case["seed"] = seed
        if not case["error"]:
            run_case(case, seed, tensors)
        else:
            case["diffusers_refuses"] = check_refused(case)
        listing["samplers"].append(case)
    save_file(tensors, str(out / "samplers.safetensors"))
    (out / "samplers.json").write_text(json.dumps(listing, indent=1) + "\n")
    size = (out / "samplers.safetensors").stat().st_size
    print(f"{len(tensors)} tensors, {size} bytes, {len(listing['samplers'])} sampler cases")


if __name__ == "__main__":
    main()
