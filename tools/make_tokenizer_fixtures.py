"""Golden data for vkdiff's CLIP tokenizer (pipeline/src/tokenizer.rs).

Writes
  tests/fixtures/pipeline/clip-tokenizer/tokenizer/    SDXL's CLIP-L tokenizer folder (pad "<|endoftext|>")
  tests/fixtures/pipeline/clip-tokenizer/tokenizer_2/  SDXL's bigG tokenizer folder (pad "!")
  tests/fixtures/pipeline/tokenizer_corpus.json        the prompts below with transformers' 77 ids for both
  pipeline/assets/clip_merges.txt                      the merges embedded as the built-in vocabulary
The ids are what diffusers' SDXL pipeline computes:
  CLIPTokenizer(vocab, merges, pad_token=P, model_max_length=77)(text, padding="max_length",
  max_length=77, truncation=True).input_ids
Written with transformers 5.23.0 (tokenizers 0.23.3) and open_clip_torch 3.3.0.
Rerun from the repository root: /tmp/ref/bin/python tools/make_tokenizer_fixtures.py
"""
import json
import pathlib
import shutil
import unicodedata

import clip_vocab

ROOT = pathlib.Path(__file__).resolve().parent.parent
FIXTURES = ROOT / "tests/fixtures/pipeline"
FOLDERS = {"tokenizer": "<|endoftext|>", "tokenizer_2": "!"}

PHOTOGRAPHY = [
    "a photo of a cat",
    "A photograph of an astronaut riding a horse",
    "portrait of a woman, 85mm lens, f/1.8, bokeh, golden hour, shot on Kodak Portra 400",
    "wide-angle landscape photo of the Dolomites at sunrise, mist in the valleys, 16mm, HDR",
    "macro shot of a dewdrop on a spider web, shallow depth of field, 100mm macro",
    "street photography, Tokyo at night, neon signs, rain-soaked pavement, cinematic lighting",
    "black and white photo of an old fisherman, Leica M6, Tri-X 400, high contrast",
    "product photo of a wristwatch on marble, studio lighting, softbox, 8k, ultra detailed",
    "aerial drone photo of a river delta, DJI Mavic 3, 4K",
    "close-up of a hummingbird in flight, 1/8000s shutter speed, ISO 3200",
    "a red apple on a wooden table, natural window light",
    "photorealistic render of a living room, Unreal Engine 5, ray tracing, octane render",
    "analog film photo, 35mm, grainy, faded colors, 1970s family picnic",
    "long exposure of car light trails on a highway at dusk",
    "underwater photo of a coral reef with clownfish, GoPro HERO12",
    "food photography: a stack of pancakes with maple syrup & blueberries",
    "a golden retriever puppy playing in the snow, telephoto, 400mm f/2.8",
    "night sky over the desert, Milky Way, star trails, Nikon Z9, 14-24mm",
    "interior of a gothic cathedral, stained glass, volumetric light rays",
    "fashion editorial, model in a yellow raincoat, overcast, muted tones",
    "RAW photo, DSLR, soft lighting, high quality, film grain, Fujifilm XT3",
    "best quality, masterpiece, ultra-detailed, 8K UHD, sharp focus",
    "a cup of coffee, steam rising, morning light, cozy cafe",
    "polaroid photo of friends at a beach bonfire",
    "tilt-shift photo of a miniature-looking city intersection",
    "infrared photograph of a forest, false color",
    "a vintage car (1957 Chevrolet Bel Air) parked in front of a diner",
    "close up photo of a rusty padlock on a blue door",
    "HDR photo of a lighthouse during a storm, waves crashing",
    "low-key portrait, chiaroscuro, Rembrandt lighting",
]

MUSHROOM_FARM = [
    "a photo of a mushroom farm",
    "oyster mushrooms growing on straw bags in a dark mushroom farm, humid air, grow lights",
    "rows of shelves with white button mushrooms (Agaricus bisporus) in a commercial mushroom farm",
    "shiitake mushrooms on oak logs, indoor farm, overhead fluorescent lighting, photo",
    "a worker in a hairnet harvesting king oyster mushrooms, mushroom farm, documentary photo",
    "close-up of lion's mane mushroom clusters on substrate blocks, macro, 60mm",
    "mushroom farm interior, polypropylene grow bags hanging from the ceiling, misting system",
    "enoki mushrooms in glass jars, laboratory, sterile, blue light",
    "a mushroom farm with 3 tiers of beds, each 1.2m wide, 25 degrees C, 90% humidity",
    "pink oyster mushrooms, pearl oyster mushrooms and blue oyster mushrooms on a shelf",
    "top-down photo of mycelium colonising a substrate block, white fluffy hyphae",
    "annotated photo of a mushroom farm: caps, stems, gills, substrate",
    "mushroom_farm_v2 shelf_03 camera=overhead lens=24mm",
    "MUSHROOM FARM, OYSTER MUSHROOMS, PHOTOREALISTIC",
    "a bag of harvested mushrooms next to a scale reading 2.5 kg",
]

PUNCTUATION = [
    "hello world!!",
    "hello world!",
    "!!!",
    "!",
    "wow!!! amazing!!!",
    "what?! really?!",
    "a!b!c",
    "!hello",
    "end.",
    "...",
    "wait... what",
    "a, b, c; d: e",
    "hyphenated-word and em—dash and en–dash",
    "quotes \"double\" and 'single'",
    "curly “double” and ‘single’ quotes",
    "«guillemets» and „German quotes“",
    "brackets [square] {curly} <angle>",
    "math: 2+2=4, 3*3=9, 10/2=5, 7-1=6, 5%",
    "email user@example.com and url https://example.com/path?q=1&r=2#frag",
    "#hashtag @mention $100 ^caret ~tilde `backtick`",
    "under_score and double__underscore",
    "pipe | and backslash \\ and slash /",
    "semicolon;colon:comma,period.",
    "ellipsis character … here",
    "•bullet ·middle dot ¶ pilcrow § section",
    "©2024 ® ™ ° ± × ÷",
    "a---b___c===d",
    "?!?!?!?!",
    "!?",
    "(!)",
    "¡Hola! ¿Qué tal?",
    "'quoted' 'twice''",
    "trailing punctuation!!! and more!!!!!!!!",
]

UNICODE = [
    "café au lait, crème brûlée, naïve résumé",
    "Straße, Fußgängerübergang, weiß",
    "STRASSE and STRAẞE",
    "İstanbul and Istanbul and ıstanbul",
    "Diyarbakır'ın",
    "東京の夜景、ネオン、雨",
    "一只猫坐在窗台上",
    "서울의 야경",
    "Москва, Красная площадь, зима",
    "Ελληνικά: ΟΔΟΣ, οδός, Σίσυφος",
    "مزرعة الفطر في الليل",
    "שלום עולם",
    "हिन्दी में एक वाक्य",
    "ภาษาไทย ไม่มีช่องว่าง",
    "Tiếng Việt có dấu",
    "emoji 😀🎉🍄🐱 party",
    "🍄🍄🍄 mushroom farm 🍄",
    "thumbs up 👍🏽 and family 👨‍👩‍👧‍👦",
    "flags 🇩🇪🇯🇵🇺🇸",
    "heart ❤️ and star ⭐ and check ✔",
    "fullwidth ＡＢＣ１２３！",
    "ｈｅｌｌｏ　ｗｏｒｌｄ",
    "ligatures ﬁ ﬂ ﬀ ﬃ",
    "superscripts x² y³ and fractions ½ ¼ ¾",
    "roman numerals Ⅻ ⅻ and circled ① ②",
    "Arabic-Indic digits ٠١٢٣٤٥٦٧٨٩",
    "Devanagari digits ०१२३",
    "combining: e\u0301 a\u0300 o\u0308 n\u0303",
    "stacked combining: a\u0301\u0327\u0308",
    "lone combining mark \u0301 here",
    "Zalgo t\u0337\u0321e\u0334\u0322x\u0335t\u0336",
    "Ǆ ǅ ǆ digraphs",
    "Å Å Å angstrom",
    "Ω Ω ohm",
    "K K kelvin",
    "math letters 𝐀𝐁𝐂 𝔸𝔹ℂ",
    "Cherokee ᏣᎳᎩ",
    "Armenian Հայերեն",
    "Georgian ქართული",
    "Amharic ኢትዮጵያ",
    "zero\u200bwidth\u200bspace",
    "zero\u200dwidth\u200cjoiners",
    "bom\ufeffinside",
    "soft\u00adhyphen",
    "no-break\u00a0space and narrow\u202fspace",
    "ideographic\u3000space",
    "line\u2028separator and paragraph\u2029separator",
    "next\u0085line",
    "mongolian\u180evowel separator",
    "left-to-right\u200emark and rtl\u200fmark",
    "private use \ue000 char",
    "replacement char \ufffd",
    "non-character \uffff",
    "supplementary 𠀀 CJK ext B",
]

NUMBERS = [
    "1024x1024",
    "3.14",
    "pi is 3.14159265358979",
    "1,000,000 dollars",
    "year 2024, 4k, 8K, 16:9 aspect ratio",
    "-5 degrees, +3 dB, 1e-5",
    "0.5 0.25 0.125",
    "007 agent",
    "v1.5 vs v2.1 vs SDXL 1.0",
    "resolution 896x1152, seed 42, steps 30, cfg 7.5",
    "12345678901234567890",
    "24mm 35mm 50mm 85mm 135mm",
    "f/1.4 1/250s ISO100",
    "#ff00aa color",
    "100% 50%off",
]

APOSTROPHES = [
    "it's a dog's life",
    "it’s a dog’s life",
    "IT'S A DOG'S LIFE",
    "don't won't can't shouldn't",
    "we're they've I'm you'll he'd",
    "WE'RE THEY'VE I'M YOU'LL HE'D",
    "rock 'n' roll",
    "'s 't 're 've 'm 'll 'd",
    "'stop' 'tree' 'real' 'very' 'moon' 'llama' 'dog'",
    "the 90's and the '80s",
    "O'Brien's pub",
    "apostrophe ʼ modifier and ` grave and ´ acute",
    "!!'s and ''s and '''",
    "dogs' toys",
]

WEIGHTS = [
    "(masterpiece:1.3), (best quality:1.2), a cat",
    "((detailed)), (((sharp))), [blurry]",
    "[cat|dog] in a field",
    "<lora:add_detail:0.8> a portrait",
    "<lora:mushroom-style_v2:1.0>, <hypernet:foo:0.5>",
    "(red:1.5) (blue:0.5) [green:yellow:0.3]",
    "a photo of (mushrooms:1.4) on a [shelf::0.2]",
    "embedding:easynegative, (worst quality:1.4)",
    "\\(escaped parentheses\\) and \\[brackets\\]",
    "{{{nai style}}} weights",
    "cat AND dog",
    "prompt BREAK another prompt",
    "(word:1.3)",
    "(!:1.2) exclamation weight",
]

SPACING = [
    "",
    " ",
    "     ",
    "\t",
    "\n",
    " \t\n\r ",
    "  leading spaces",
    "trailing spaces   ",
    "multiple    spaces   between   words",
    "tabs\tbetween\twords",
    "new\nlines\nhere",
    "windows\r\nline endings",
    "vertical\x0btab and form\x0cfeed",
    "mixed \t \n whitespace",
    "control \x00 null \x01 soh \x07 bell \x1b escape \x7f del",
    "information separators \x1c\x1d\x1e\x1f here",
    "nospaces,justpunctuation.andwords",
]

SPECIALS = [
    "<|endoftext|>",
    "<|startoftext|>",
    "a <|endoftext|> b",
    "a<|endoftext|>b",
    "<|startoftext|>a photo<|endoftext|>",
    "<|ENDOFTEXT|>",
    "<|EndOfText|> and <|StartOfText|>",
    "<|endoftext|><|endoftext|><|endoftext|>",
    "<|endoftext|!>",
    "<|endoftext",
    "endoftext|>",
    "<|endoftext|>!",
    "!<|endoftext|>!",
    "<|endoftext|>" * 80,
    "<pad> <unk> <s> </s> [PAD] [CLS]",
    "word</w> and </w>",
]

UPPERCASE = [
    "A PHOTO OF A CAT",
    "ALL CAPS PROMPT WITH NUMBERS 123 AND PUNCTUATION!!!",
    "CamelCaseWords and snake_case_words",
    "ÉCOLE ÇA ÑANDÚ ÆØÅ",
    "ΣΊΣΥΦΟΣ",
    "DŽUNGLA",
]

WORD = "photograph of a mushroom farm with shelves, "
LONG = [
    WORD * 6,
    "a " * 80,
    "a" * 200,
    "!" * 100,
    "! " * 100,
    "!a" * 60,
    "mushroom " * 75,
    "mushroom " * 74 + "farm",
    "mushroom " * 76,
    "supercalifragilisticexpialidocious antidisestablishmentarianism pneumonoultramicroscopicsilicovolcanoconiosis",
    "1234567890" * 10,
    "🍄" * 40,
    "东京" * 50,
    "x" * 1000,
    " ".join(f"word{i}" for i in range(60)),
    "a very long prompt describing a highly detailed photograph of an indoor mushroom farm with many "
    "rows of metal shelves holding oyster mushroom grow bags, a worker in a white coat inspecting the "
    "caps under warm sodium lamps, condensation on the walls, a humidifier in the corner, a clipboard "
    "with handwritten notes, cinematic composition, 35mm lens, shallow depth of field, award winning",
]


def variations(prompts):
    """Case, normalisation-form and pad-sensitive variants of the prompts that have letters."""
    out = []
    for p in prompts:
        nfd = unicodedata.normalize("NFD", p)
        if nfd != p:
            out.append(nfd)
        out += [p.upper(), p + "!", p.title()]
    return out


def corpus():
    base = PHOTOGRAPHY + MUSHROOM_FARM + PUNCTUATION + UNICODE + NUMBERS + APOSTROPHES + WEIGHTS
    base += SPACING + SPECIALS + UPPERCASE + LONG
    prompts = base + variations(PHOTOGRAPHY[:8] + MUSHROOM_FARM[:4] + UNICODE[:12] + APOSTROPHES[:6])
    unique = list(dict.fromkeys(prompts))
    assert len(unique) >= 250, len(unique)
    return unique


def main():
    out = FIXTURES / "clip-tokenizer"
    tokenizers = {}
    for name, pad in FOLDERS.items():
        clip_vocab.write_tokenizer(out / name, pad)
        tokenizers[name] = clip_vocab.hf_tokenizer(out / name)
    assets = ROOT / "pipeline/assets"
    assets.mkdir(exist_ok=True)
    shutil.copyfile(out / "tokenizer/merges.txt", assets / "clip_merges.txt")

    cases = []
    for text in corpus():
        case = {"text": text}
        for name, tok in tokenizers.items():
            ids = tok(text, padding="max_length", max_length=77, truncation=True).input_ids
            assert len(ids) == 77, (text, ids)
            case[name] = ids
        cases.append(case)
    # One case a line keeps the file small and its diffs readable.
    lines = ",\n".join("  " + json.dumps(case) for case in cases)
    header = json.dumps({"generator": "tools/make_tokenizer_fixtures.py (transformers 5.23.0 CLIPTokenizer)",
                         "pad_tokens": FOLDERS})
    (FIXTURES / "tokenizer_corpus.json").write_text(header[:-1] + ',\n "cases": [\n' + lines + "\n ]\n}\n")
    print(f"{len(cases)} prompts written to {FIXTURES / 'tokenizer_corpus.json'}")


if __name__ == "__main__":
    main()
