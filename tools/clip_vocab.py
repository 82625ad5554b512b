"""The real CLIP BPE vocabulary in the Hugging Face tokenizer layout, built from the merges list
that open_clip ships (bpe_simple_vocab_16e6.txt.gz), the way open_clip builds its own vocabulary.

Used by the fixture scripts; written with open_clip_torch 3.3.0 and transformers 5.23.0.
"""
import gzip
import json
import pathlib

from open_clip import tokenizer as oc_tok

MERGES = 49152 - 256 - 2  # open_clip keeps the first 48894 merges: 512 byte symbols + merges + 2 specials = 49408
BOS, EOS = "<|startoftext|>", "<|endoftext|>"


def merges():
    lines = gzip.open(oc_tok.default_bpe()).read().decode("utf-8").split("\n")
    return [tuple(m.split()) for m in lines[1 : MERGES + 1]]


def vocab():
    symbols = list(oc_tok.bytes_to_unicode().values())
    symbols += [s + "</w>" for s in symbols]
    symbols += ["".join(m) for m in merges()]
    symbols += [BOS, EOS]
    assert len(symbols) == 49408
    return {s: i for i, s in enumerate(symbols)}


def write_tokenizer(folder, pad_token):
    """vocab.json, merges.txt and the token configs of an SDXL `tokenizer/` (pad_token
    "<|endoftext|>") or `tokenizer_2/` (pad_token "!") folder."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "vocab.json").write_text(json.dumps(vocab(), ensure_ascii=False))
    (folder / "merges.txt").write_text("#version: 0.2\n" + "\n".join(" ".join(m) for m in merges()) + "\n")
    special = dict(bos_token=BOS, eos_token=EOS, unk_token=EOS, pad_token=pad_token)
    (folder / "special_tokens_map.json").write_text(json.dumps(special, indent=2))
    config = dict(special, model_max_length=77, do_lower_case=True, tokenizer_class="CLIPTokenizer")
    (folder / "tokenizer_config.json").write_text(json.dumps(config, indent=2))


def hf_tokenizer(folder):
    """transformers' CLIPTokenizer for a folder written above, built explicitly: transformers 5
    mis-loads a CLIP folder that has no tokenizer.json (the real SDXL layout)."""
    from transformers import CLIPTokenizer

    folder = pathlib.Path(folder)
    pad = json.loads((folder / "special_tokens_map.json").read_text())["pad_token"]
    tok = CLIPTokenizer(str(folder / "vocab.json"), str(folder / "merges.txt"), pad_token=pad, model_max_length=77)
    ids = tok("a photo of a cat").input_ids
    assert ids == [49406, 320, 1125, 539, 320, 2368, 49407], ids
    return tok
