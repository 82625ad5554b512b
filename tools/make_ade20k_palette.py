#!/usr/bin/env python3
"""Writes render/src/control/ade20k.rs: ADE20K's 150 class names (mmsegmentation's ADE20KDataset)
with the colour each has in the palette the segmentation ControlNets were trained on
(controlnet_aux's ade_palette(), the UniFormer annotator's), checked to be the same palette.

    pip install --no-deps mmsegmentation controlnet_aux   # 1.2.2 and 0.0.10 made the file
    python tools/make_ade20k_palette.py

Both are read as source text (ast), so neither package's dependencies are needed."""
import ast
import importlib.util
import pathlib
from importlib.metadata import version

ROOT = pathlib.Path(__file__).resolve().parent.parent


def source(package, relative):
    return pathlib.Path(importlib.util.find_spec(package).submodule_search_locations[0]) / relative


def mmseg_metainfo():
    tree = ast.parse(source("mmseg", "datasets/ade.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "METAINFO" for t in node.targets):
            call = node.value
            return {k.arg: ast.literal_eval(k.value) for k in call.keywords}
    raise SystemExit("no METAINFO in mmseg/datasets/ade.py")


def controlnet_aux_palette():
    tree = ast.parse(source("controlnet_aux", "util.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "ade_palette":
            return ast.literal_eval(node.body[-1].value)
    raise SystemExit("no ade_palette in controlnet_aux/util.py")


meta = mmseg_metainfo()
names, palette = meta["classes"], meta["palette"]
assert len(names) == 150 and palette == controlnet_aux_palette(), "the two ADE20K palettes differ"
lines = [
    "//! ADE20K's 150 classes with their colours in the segmentation ControlNets' palette. Written by",
    f"//! tools/make_ade20k_palette.py from mmsegmentation {version('mmsegmentation')} (class names) and",
    f"//! controlnet_aux {version('controlnet_aux')} (`ade_palette`, the same colours); do not edit.",
    "",
    "/// (class name, RGB), in ADE20K's class order.",
    "pub const ADE20K: [(&str, [u8; 3]); 150] = [",
]
lines += [f'    ("{n.strip()}", [{r}, {g}, {b}]),' for n, (r, g, b) in zip(names, palette)]
lines.append("];")
(ROOT / "render/src/control/ade20k.rs").write_text("\n".join(lines) + "\n")
print("wrote render/src/control/ade20k.rs")
