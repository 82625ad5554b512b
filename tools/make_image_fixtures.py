"""Fixtures for pipeline/tests/images.rs: small input images and what the Python reference makes
of them.

Made with Pillow 13.0.0, torch 2.15.0 (CPU, AVX512 capability: ATen's native uint8 resize),
torchvision 0.29.2, transformers 5.23.0, diffusers 0.42.1, numpy 2, OpenEXR 3.5.3 (pip).
Rerun from the repository root with that environment:

    python tools/make_image_fixtures.py

It rewrites tests/fixtures/images/: the inputs (*.png, *.jpg, *.exr), `expected.bin` (every
expected output concatenated: uint8 images as raw HWC bytes, float tensors as little-endian
float32) and `index.json` (what each entry is, with its byte range in expected.bin).
"""

import io
import json
import struct
import zlib
from pathlib import Path

import numpy as np
import OpenEXR
import PIL.Image
import torch
import torchvision.transforms.v2.functional as tvF
from diffusers.image_processor import VaeImageProcessor
from transformers import CLIPImageProcessor

OUT = Path(__file__).resolve().parent.parent / "tests" / "fixtures" / "images"
rng = np.random.default_rng(20260521)
expected = bytearray()
index = {"png": [], "jpeg": [], "pil_resize": [], "torch_resize": [], "control": [], "clip": [], "exr": []}


def blob(data: bytes) -> list:
    start = len(expected)
    expected.extend(data)
    return [start, len(expected)]


def chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def write_png(name, samples, color_type, bit_depth, plte=None, trns=None):
    """A PNG written by hand, so every colour type and bit depth can be made (PIL cannot).
    `samples`: rows of samples, (height, width * channels)."""
    h = samples.shape[0]
    w = samples.shape[1] // {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[color_type]
    rows = []
    for r in samples.reshape(h, -1):
        if bit_depth == 16:
            rows.append(b"".join(struct.pack(">H", int(v)) for v in r))
        elif bit_depth == 8:
            rows.append(bytes(int(v) for v in r))
        else:
            acc, n, row = 0, 0, bytearray()
            for v in r:
                acc, n = (acc << bit_depth) | int(v), n + bit_depth
                if n == 8:
                    row.append(acc)
                    acc, n = 0, 0
            if n:
                row.append(acc << (8 - n))
            rows.append(bytes(row))
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, bit_depth, color_type, 0, 0, 0))
    if plte is not None:
        data += chunk(b"PLTE", plte)
    if trns is not None:
        data += chunk(b"tRNS", trns)
    data += chunk(b"IDAT", zlib.compress(b"".join(b"\x00" + r for r in rows))) + chunk(b"IEND", b"")
    (OUT / name).write_bytes(data)


def smooth_image(w, h):
    """Gradients plus noise plus a hard edge: exercises rounding, clipping and overshoot."""
    y, x = np.mgrid[0:h, 0:w]
    img = np.stack([255 * x / max(w - 1, 1), 255 * y / max(h - 1, 1), 128 + 100 * np.sin(x / 3.0 + y / 5.0)], -1)
    img += rng.normal(0, 20, img.shape)
    img[:, w // 2 : w // 2 + 2] = [255, 0, 255]
    return np.clip(img, 0, 255).astype(np.uint8)


def pngs():
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
    for ct, bd in [(0, 1), (0, 2), (0, 4), (0, 8), (0, 16), (2, 8), (2, 16), (3, 1), (3, 2), (3, 4), (3, 8),
                   (4, 8), (4, 16), (6, 8), (6, 16)]:
        w, h = 7, 3
        vals = rng.integers(0, 1 << bd, size=(h, w * channels[ct]))
        if ct == 0 and bd == 16:
            vals[0, :4] = [0, 200, 255, 256]  # PIL clips I;16 to 255 on its way to RGB
        plte = bytes(rng.integers(0, 256, 3 * (1 << bd)).astype(np.uint8)) if ct == 3 else None
        name = f"png_c{ct}_b{bd}.png"
        write_png(name, vals, ct, bd, plte)
        add_png(name)
    # Grey with a tRNS colour and a palette with tRNS: PIL drops the transparency for RGB.
    write_png("png_c0_b8_trns.png", rng.integers(0, 256, size=(2, 5)), 0, 8, trns=struct.pack(">H", 7))
    add_png("png_c0_b8_trns.png")
    write_png("png_c3_b8_trns.png", rng.integers(0, 4, size=(2, 5)), 3, 8,
              plte=bytes(rng.integers(0, 256, 12).astype(np.uint8)), trns=bytes([0, 128]))
    add_png("png_c3_b8_trns.png")


def add_png(name):
    im = PIL.Image.open(OUT / name)
    rgb = np.asarray(im.convert("RGB"))
    index["png"].append({"file": name, "pil_mode": im.mode, "width": rgb.shape[1], "height": rgb.shape[0],
                         "rgb": blob(rgb.tobytes())})


def jpeg():
    PIL.Image.fromarray(smooth_image(21, 13)).save(OUT / "photo.jpg", quality=90)
    rgb = np.asarray(PIL.Image.open(OUT / "photo.jpg").convert("RGB"))
    index["jpeg"].append({"file": "photo.jpg", "width": 21, "height": 13, "rgb": blob(rgb.tobytes())})


FILTERS = {"bilinear": PIL.Image.BILINEAR, "bicubic": PIL.Image.BICUBIC, "lanczos": PIL.Image.LANCZOS}


def resizes():
    sources = {"src_37x29.png": smooth_image(37, 29), "src_1x1.png": smooth_image(1, 1),
               "src_5x1.png": smooth_image(5, 1), "src_64x8.png": smooth_image(64, 8)}
    for name, arr in sources.items():
        PIL.Image.fromarray(arr).save(OUT / name)
    sizes = {"src_37x29.png": [(37, 29), (64, 48), (19, 15), (12, 40), (50, 7), (1, 1), (3, 2), (37, 10), (8, 29), (74, 58)],
             "src_1x1.png": [(1, 1), (4, 3), (2, 1)],
             "src_5x1.png": [(2, 1), (9, 3), (1, 1)],
             "src_64x8.png": [(7, 3), (16, 2), (5, 8)]}
    for name, targets in sizes.items():
        im = PIL.Image.open(OUT / name)
        for w, h in targets:
            for filt, code in FILTERS.items():
                out = np.asarray(im.resize((w, h), resample=code))
                index["pil_resize"].append({"file": name, "filter": filt, "width": w, "height": h,
                                            "rgb": blob(out.tobytes())})
            for filt, mode in [("bicubic", tvF.InterpolationMode.BICUBIC), ("bilinear", tvF.InterpolationMode.BILINEAR)]:
                t = torch.from_numpy(np.asarray(im)).permute(2, 0, 1).contiguous()
                try:
                    out = tvF.resize(t, [h, w], interpolation=mode, antialias=True).permute(1, 2, 0).contiguous()
                except RuntimeError as e:  # ATen's AVX kernel asserts on some 1-pixel outputs
                    print(f"torch cannot resize {name} to {w}x{h} ({filt}): {str(e).splitlines()[0][:60]}")
                    continue
                index["torch_resize"].append({"file": name, "filter": filt, "width": w, "height": h,
                                              "rgb": blob(out.numpy().tobytes())})


def controls():
    proc = VaeImageProcessor(vae_scale_factor=8, do_convert_rgb=True, do_normalize=False)
    for name, w, h in [("src_37x29.png", 64, 48), ("src_37x29.png", 30, 21), ("src_64x8.png", 64, 8),
                       ("src_64x8.png", 16, 16)]:
        t = proc.preprocess(PIL.Image.open(OUT / name), height=h, width=w).to(torch.float32)
        index["control"].append({"file": name, "width": w, "height": h, "shape": list(t.shape),
                                 "values": blob(t.numpy().astype("<f4").tobytes())})


def clips():
    # Exactly as diffusers' load_ip_adapter builds it when there is no preprocessor_config.json.
    default = CLIPImageProcessor(size=56, crop_size=56)
    assert type(default).__mro__[1].__name__ == "TorchvisionBackend", type(default).__mro__
    PIL.Image.fromarray(smooth_image(90, 70)).save(OUT / "src_90x70.png")
    PIL.Image.fromarray(smooth_image(20, 33)).save(OUT / "src_20x33.png")
    configs = {
        "default56": None,
        "clip_bilinear_crop": {"image_processor_type": "CLIPImageProcessor", "size": {"shortest_edge": 32},
                               "crop_size": {"height": 24, "width": 30}, "resample": 2, "do_convert_rgb": True,
                               "image_mean": [0.5, 0.5, 0.5], "image_std": [0.5, 0.5, 0.5], "unknown_key": 1},
        "clip_pad_crop": {"size": 20, "crop_size": 28, "rescale_factor": 0.00392156862745098},
        "clip_no_normalize": {"feature_extractor_type": "CLIPFeatureExtractor", "size": {"shortest_edge": 16},
                              "crop_size": 16, "do_normalize": False},
    }
    for cfg_name, cfg in configs.items():
        if cfg is None:
            proc = default
        else:
            folder = OUT / cfg_name
            folder.mkdir(exist_ok=True)
            (folder / "preprocessor_config.json").write_text(json.dumps(cfg, indent=1))
            proc = CLIPImageProcessor.from_pretrained(str(folder))
        for name in ["src_37x29.png", "src_90x70.png", "src_20x33.png"]:
            t = proc(PIL.Image.open(OUT / name), return_tensors="pt").pixel_values
            index["clip"].append({"config": cfg_name, "file": name, "shape": list(t.shape),
                                  "values": blob(t.numpy().astype("<f4").tobytes())})


def exrs():
    w, h = 11, 7
    depth = (0.8 + 0.4 * rng.random((h, w))).astype(np.float32)
    depth[0, 0] = np.inf  # background: invalid, black
    depth[1, 2] = 0.0
    cases = [
        ("depth_z_zip.exr", {"Z": depth}, OpenEXR.ZIP_COMPRESSION),
        ("depth_blender_piz.exr", {"ViewLayer.Combined.R": np.full_like(depth, 0.5), "ViewLayer.Combined.G": np.zeros_like(depth),
                                   "ViewLayer.Depth.Z": depth, "ViewLayer.Combined.B": np.zeros_like(depth)}, OpenEXR.PIZ_COMPRESSION),
        ("depth_v_rle.exr", {"V": depth, "Y": depth * 2}, OpenEXR.RLE_COMPRESSION),
        ("depth_half_piz.exr", {"Z": depth.astype(np.float16)}, OpenEXR.PIZ_COMPRESSION),
        ("no_depth.exr", {"Y": depth, "A": depth}, OpenEXR.ZIP_COMPRESSION),
        ("two_layers.exr", {"A.Depth.Z": depth, "B.Depth.Z": depth}, OpenEXR.ZIP_COMPRESSION),
    ]
    for name, channels, compression in cases:
        header = {"compression": compression, "type": OpenEXR.scanlineimage}
        stored = next((v for k, v in channels.items() if k in ("Z", "V") or k.endswith("Depth.Z")), depth)
        OpenEXR.File(header, dict(channels)).write(str(OUT / name))
        index["exr"].append({"file": name, "width": w, "height": h,
                             "depth": blob(stored.astype("<f4").tobytes())})


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    pngs()
    jpeg()
    resizes()
    controls()
    clips()
    exrs()
    (OUT / "expected.bin").write_bytes(bytes(expected))
    (OUT / "index.json").write_text(json.dumps(index, indent=0))
    total = sum(p.stat().st_size for p in OUT.iterdir())
    print(f"{len(expected)} expected bytes; fixtures {total} bytes")


if __name__ == "__main__":
    main()
