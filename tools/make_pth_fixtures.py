"""Writes tests/fixtures/pth/: tiny checkpoints as torch.save writes them, for formats/tests/torch_pth.rs.

  zip.pth         a dict of tensors, zip format (torch >= 1.6 default): float32 incl. a transposed view,
                  views sharing one storage at offsets, a broadcast (stride 0) view, a 0-d scalar, an empty
                  tensor, an nn.Parameter, and float16, bfloat16 and float64 tensors
  zip-proto4.pth  the same dict pickled at protocol 4 (FRAME, MEMOIZE, STACK_GLOBAL, SHORT_BINUNICODE)
  legacy.pth      the same dict, _use_new_zipfile_serialization=False
  module.pth      state_dict() of Conv2d + BatchNorm2d (an OrderedDict, with int64 num_batches_tracked)
  expected.safetensors  every float tensor above, converted to float32 and made contiguous

Run with a python that has torch and safetensors: /tmp/ref/bin/python tools/make_pth_fixtures.py
"""

import os

import torch
from safetensors.torch import save_file

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures", "pth")


def main():
    torch.manual_seed(0)
    base = torch.randn(4, 6)
    tensors = {
        "weight": torch.randn(3, 4),
        "transposed": torch.randn(4, 5).t(),
        "base": base,
        "rows": base[1:3],  # shares base's storage at offset 6
        "column": base[:, 2],  # offset 2, stride 6
        "broadcast": torch.randn(3, 1).expand(3, 4),  # stride 0
        "scalar": torch.tensor(3.5),
        "empty": torch.zeros(0, 3),
        "param": torch.nn.Parameter(torch.randn(2)),
        "half": torch.randn(2, 3).half(),
        "bf16": torch.randn(5).bfloat16(),
        "double": torch.randn(2, 2).double(),
    }
    module = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4))
    module.train()(torch.randn(2, 3, 5, 5))  # running stats and num_batches_tracked move off their defaults
    state = module.state_dict()

    os.makedirs(OUT, exist_ok=True)
    torch.save(tensors, os.path.join(OUT, "zip.pth"))
    torch.save(tensors, os.path.join(OUT, "zip-proto4.pth"), pickle_protocol=4)
    torch.save(tensors, os.path.join(OUT, "legacy.pth"), _use_new_zipfile_serialization=False)
    torch.save(state, os.path.join(OUT, "module.pth"))

    # a contiguous copy: safetensors refuses views and tensors that share memory
    everything = {**tensors, **state}
    contiguous = torch.contiguous_format
    expected = {name: t.detach().float().clone(memory_format=contiguous) for name, t in everything.items() if t.is_floating_point()}
    save_file(expected, os.path.join(OUT, "expected.safetensors"))
    for name in sorted(os.listdir(OUT)):
        print(f"{name}: {os.path.getsize(os.path.join(OUT, name))} bytes")
    print(f"torch {torch.__version__}")


if __name__ == "__main__":
    main()
