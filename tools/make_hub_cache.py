#!/usr/bin/env python3
"""A Hugging Face hub cache of the tiny fixtures, laid out by huggingface_hub's own functions, for
the tests of model flags that take a Hugging Face id (tests/hub_cli.rs).

Versions used to write the committed fixture: Python 3.11, huggingface_hub 2.4.0, diffusers 0.42.1.
Setup and rerun:
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install huggingface_hub diffusers torch transformers
  /tmp/ref/bin/python tools/make_hub_cache.py [--out tests/fixtures/hub]

Each repository below becomes `models--ORG--NAME/` with `refs/main` (and `refs/v1` for the SDXL)
naming a commit, `snapshots/COMMIT/` whose files are huggingface_hub's relative links into
`blobs/`, and `blobs/HASH` named as the hub names them (the sha256 of an LFS file, the git blob
sha1 of any other). One liberty: each blob is itself a relative link to the fixture file it holds
(tests/fixtures/...), so the repository does not carry the tiny models twice; readers follow
links, so the tree reads as a real cache. The script then checks it with huggingface_hub's own
readers (`scan_cache_dir`, `try_to_load_from_cache`) and loads the SDXL from it with diffusers'
`from_pretrained(id, local_files_only=True)`.
"""
import argparse
import hashlib
import os
import pathlib
import shutil

import huggingface_hub
from huggingface_hub import scan_cache_dir, try_to_load_from_cache
from huggingface_hub.file_download import (
    _cache_commit_hash_for_specific_revision,
    _create_symlink,
    _get_pointer_path,
    repo_folder_name,
)

FIXTURES = pathlib.Path(__file__).resolve().parent.parent / "tests" / "fixtures"

# repository id -> {path in the repository: fixture file}
REPOS = {
    "vkdiff-test/tiny-sdxl": {
        str(p.relative_to(FIXTURES / "pipeline/tiny-sdxl")): p
        for p in sorted((FIXTURES / "pipeline/tiny-sdxl").rglob("*")) if p.is_file()
    },
    "vkdiff-test/controlnet-depth": {
        "config.json": FIXTURES / "workflow/controlnet/config.json",
        "diffusion_pytorch_model.fp16.safetensors": FIXTURES / "workflow/controlnet/diffusion_pytorch_model.fp16.safetensors",
    },
    # As xinsir/controlnet-union-sdxl-1.0 holds them: the Union model and its ProMax file side by side.
    "vkdiff-test/controlnet-union-sdxl-1.0": {
        "config.json": FIXTURES / "workflow/controlnet-union/config.json",
        "diffusion_pytorch_model.safetensors": FIXTURES / "workflow/controlnet-union/diffusion_pytorch_model.safetensors",
        "diffusion_pytorch_model_promax.safetensors": FIXTURES / "workflow/controlnet-union-promax.safetensors",
    },
    "vkdiff-test/IP-Adapter": {
        "sdxl_models/ip-adapter_sdxl.safetensors": FIXTURES / "workflow/ip-adapter_tiny.safetensors",
        "sdxl_models/image_encoder/config.json": FIXTURES / "workflow/image_encoder/config.json",
        "sdxl_models/image_encoder/model.safetensors": FIXTURES / "workflow/image_encoder/model.safetensors",
    },
    "vkdiff-test/lora": {"pytorch_lora_weights.safetensors": FIXTURES / "workflow/lora-peft.safetensors"},
    "vkdiff-test/tiny-vae-fp16-fix": {
        "config.json": FIXTURES / "vae_swap/tiny-vae/config.json",
        "diffusion_pytorch_model.safetensors": FIXTURES / "vae_swap/tiny-vae/diffusion_pytorch_model.safetensors",
        "sdxl_vae.safetensors": FIXTURES / "vae_swap/tiny-vae/sdxl_vae.safetensors",
    },
}


def etag(path):
    """The hub's name for a file's blob: sha256 for LFS files (weights), git's blob sha1 otherwise."""
    data = path.read_bytes()
    if path.suffix in (".safetensors", ".bin"):
        return hashlib.sha256(data).hexdigest()
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def commit_of(files):
    """A stable stand-in for the repository's commit hash."""
    h = hashlib.sha1()
    for name, path in sorted(files.items()):
        h.update(name.encode() + b"\0" + etag(path).encode())
    return h.hexdigest()


def write_repo(cache, repo_id, files, revisions):
    storage = cache / repo_folder_name(repo_id=repo_id, repo_type="model")
    commit = commit_of(files)
    for name, source in files.items():
        blob = storage / "blobs" / etag(source)
        blob.parent.mkdir(parents=True, exist_ok=True)
        if not blob.is_symlink():
            blob.symlink_to(os.path.relpath(source, blob.parent))
        pointer = pathlib.Path(_get_pointer_path(str(storage), commit, name))
        pointer.parent.mkdir(parents=True, exist_ok=True)
        _create_symlink(str(blob), str(pointer), new_blob=False)
    for revision in revisions:
        _cache_commit_hash_for_specific_revision(str(storage), revision, commit)
    return commit


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(FIXTURES / "hub"))
    args = ap.parse_args()
    cache = pathlib.Path(args.out).resolve()
    if cache.exists():
        shutil.rmtree(cache)
    for repo_id, files in REPOS.items():
        revisions = ["main", "v1"] if repo_id.endswith("tiny-sdxl") else ["main"]
        commit = write_repo(cache, repo_id, files, revisions)
        print(f"{repo_id}: {len(files)} files at {commit}")

    info = scan_cache_dir(cache)
    assert not info.warnings, info.warnings
    assert {r.repo_id for r in info.repos} == set(REPOS), info.repos
    for repo_id, files in REPOS.items():
        for name, source in files.items():
            found = try_to_load_from_cache(repo_id, name, cache_dir=cache)
            assert isinstance(found, str) and pathlib.Path(found).read_bytes() == source.read_bytes(), (repo_id, name)
    import diffusers
    import torch
    pipe = diffusers.StableDiffusionXLPipeline.from_pretrained(
        "vkdiff-test/tiny-sdxl", cache_dir=cache, local_files_only=True, torch_dtype=torch.float32)
    print("diffusers loaded vkdiff-test/tiny-sdxl offline:", type(pipe).__name__,
          f"(huggingface_hub {huggingface_hub.__version__}, diffusers {diffusers.__version__})")


if __name__ == "__main__":
    main()
