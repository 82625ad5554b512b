use crate::common::*;
use vkdiff_lora::{LoraFile, LoraMerger, Targets};
use vkdiff_networks::{unet_names, Parameters};
use vkdiff_runtime::Dtype;

/// Matrix and conv weights: (name, PyTorch shape).
fn weights(params: &Parameters) -> Vec<(String, Vec<usize>)> {
    params
        .names()
        .into_iter()
        .filter(|n| n.ends_with(".weight"))
        .map(|n| (n.to_string(), params.get(n).unwrap().torch_shape.clone()))
        .filter(|(_, s)| s.len() >= 2)
        .collect()
}

fn module(weight: &str) -> &str {
    weight.strip_suffix(".weight").unwrap()
}

fn flat(s: &str) -> String {
    s.replace('.', "_")
}

/// kohya tensors for one module; `alpha` None leaves the alpha out (scale 1).
fn kohya(name: &str, f: &Factors, alpha: Option<f32>) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    let mut t = vec![
        (format!("{name}.lora_down.weight"), f.down_shape(), f.down.clone()),
        (format!("{name}.lora_up.weight"), f.up_shape(), f.up.clone()),
    ];
    if let Some(a) = alpha {
        t.push((format!("{name}.alpha"), vec![], vec![a]));
    }
    t
}

/// The not-run last layer of CLIP-L, which the loaded network lacks.
fn clip_l_last_layer(nets: &Nets) -> Vec<(String, Vec<usize>)> {
    let c = nets.clip_l.config();
    let (h, i, l) = (c.hidden_size, c.intermediate_size, c.num_hidden_layers - 1);
    let p = format!("text_model.encoder.layers.{l}");
    ["self_attn.q_proj", "self_attn.k_proj", "self_attn.v_proj", "self_attn.out_proj"]
        .iter()
        .map(|m| (format!("{p}.{m}.weight"), vec![h, h]))
        .chain([(format!("{p}.mlp.fc1.weight"), vec![i, h]), (format!("{p}.mlp.fc2.weight"), vec![h, i])])
        .collect()
}

/// A kohya file in sd-scripts' own naming (original UNet paths) over every weight of all three
/// networks, plus CLIP-L's not-run last layer; ranks, alphas and absent alphas vary.
fn kohya_ldm_everything(nets: &Nets, dtype: Dtype, strength: f64) {
    let original = unet_names(nets.unet.config()).unwrap();
    let mut tensors = Vec::new();
    let mut expected = Expected::new();
    let parts: [(&str, &Parameters); 3] = [
        ("lora_unet_", nets.unet.parameters()),
        ("lora_te1_", nets.clip_l.parameters()),
        ("lora_te2_", nets.big_g.parameters()),
    ];
    let mut seed = 10;
    let mut counts = [0; 3];
    for (c, (prefix, params)) in parts.iter().enumerate() {
        let mut list = weights(params);
        if c == 1 {
            list.extend(clip_l_last_layer(nets));
        }
        for (weight, shape) in list {
            seed += 2;
            let rank = if shape.len() == 4 && shape[2] == 3 { 2 } else { 1 + (seed as usize % 4) };
            let alpha = match seed % 3 {
                0 => None,
                1 => Some(1.0),
                _ => Some(rank as f32 * 2.0),
            };
            let f = Factors::new(c, &weight, &shape, rank, alpha.map_or(1.0, |a| a as f64 / rank as f64), seed);
            let path = if c == 0 { original.rename(&weight).unwrap().name } else { weight.clone() };
            tensors.extend(kohya(&format!("{prefix}{}", flat(module(&path))), &f, alpha));
            if params.get(&weight).is_some() {
                expected.add(nets.params(), &f, strength);
                counts[c] += 1;
            }
        }
    }
    let path = scratch(&format!("kohya-ldm-{dtype:?}.safetensors")).join("lora.safetensors");
    write(&path, &tensors, &[]);
    let lora = LoraFile::open(&path).unwrap();
    let before = [nets.unet.parameters(), nets.clip_l.parameters(), nets.big_g.parameters()].map(snapshot);
    let mut merger = LoraMerger::new();
    let summary =
        merger.apply(&Targets::sdxl(&nets.unet, &nets.clip_l, &nets.big_g), &[(&lora, strength as f32)]).unwrap();
    let s = &summary.loras[0];
    assert_eq!(
        [s.unet, s.text_encoder_1, s.text_encoder_2, s.not_run],
        [counts[0], counts[1], counts[2], 6],
        "{summary}"
    );
    assert!(counts[0] > 60 && counts[1] == 12 && counts[2] == 12, "{counts:?}");
    expected.check(nets.params(), dtype);
    merger.restore().unwrap();
    for (b, (what, params)) in before.iter().zip(parts) {
        assert_restored(what, b, params);
    }
}

#[test]
fn kohya_ldm_every_weight_f32() {
    kohya_ldm_everything(&tiny_sdxl(Dtype::F32), Dtype::F32, 0.8);
}

#[test]
fn kohya_ldm_every_weight_f16() {
    kohya_ldm_everything(&tiny_sdxl(Dtype::F16), Dtype::F16, 0.8);
}

/// Attention, feed-forward, projections and convs of the UNet, and one layer of each text encoder.
fn selection(nets: &Nets, unet_filter: impl Fn(&str) -> bool, layer: usize) -> [Vec<(String, Vec<usize>)>; 3] {
    let in_layer = |n: &String| n.starts_with(&format!("text_model.encoder.layers.{layer}."));
    [
        weights(nets.unet.parameters()).into_iter().filter(|(n, _)| unet_filter(n)).collect(),
        weights(nets.clip_l.parameters()).into_iter().filter(|(n, _)| in_layer(n)).collect(),
        weights(nets.big_g.parameters()).into_iter().filter(|(n, _)| in_layer(n)).collect(),
    ]
}

/// A kohya file in diffusers module paths (no alphas) and a PEFT file with adapter metadata.
fn diffusers_pair(nets: &Nets, dtype: Dtype) -> (LoraFile, Vec<Factors>, LoraFile, Vec<Factors>) {
    let sel = selection(
        nets,
        |n| n.contains("attentions") || n.contains("resnets.0.conv1") || n.contains("conv_shortcut"),
        0,
    );
    let mut tensors = Vec::new();
    let mut kohya_factors = Vec::new();
    for (net, ((prefix, list), seed)) in
        ["lora_unet_", "lora_te1_", "lora_te2_"].iter().zip(&sel).zip([100, 200, 300]).enumerate()
    {
        for (i, (w, shape)) in list.iter().enumerate() {
            let f = Factors::new(net, w, shape, 3, 1.0, seed + 2 * i as u64);
            tensors.extend(kohya(&format!("{prefix}{}", flat(module(w))), &f, None));
            kohya_factors.push(f);
        }
    }
    let kohya_path = scratch(&format!("kohya-diffusers-{dtype:?}.safetensors")).join("lora.safetensors");
    write(&kohya_path, &tensors, &[]);

    // PEFT: UNet lora_alpha 8 with patterns (one module by full path, every ff.net.2 by suffix),
    // CLIP-L under rsLoRA, bigG without metadata (scale 1).
    let sel = selection(nets, |n| n.contains("attn") || n.contains("ff.net") || n.contains("downsamplers"), 1);
    let (r, special) = (4usize, sel[0].iter().find(|(n, _)| n.contains("attn2.to_k")).unwrap().0.clone());
    let special = module(&special).to_string();
    let scale = |c: usize, w: &str| match c {
        0 if w.starts_with(&special) => 2.0 / r as f64,
        0 if w.contains("ff.net.2") => 16.0 / r as f64,
        0 => 8.0 / r as f64,
        1 => 4.0 / (r as f64).sqrt(),
        _ => 1.0,
    };
    let mut tensors = Vec::new();
    let mut peft_factors = Vec::new();
    for (c, (prefix, list)) in ["unet.", "text_encoder.", "text_encoder_2."].iter().zip(&sel).enumerate() {
        for (i, (w, shape)) in list.iter().enumerate() {
            let f = Factors::new(c, w, shape, r, scale(c, w), 1000 + 7 * c as u64 + 2 * i as u64);
            let m = format!("{prefix}{}", module(w));
            // PEFT's in-memory names carry the adapter name; accept both spellings.
            let a = if i % 2 == 0 { format!("{m}.lora_A.weight") } else { format!("{m}.lora_A.default.weight") };
            tensors.push((a, f.down_shape(), f.down.clone()));
            tensors.push((format!("{m}.lora_B.weight"), f.up_shape(), f.up.clone()));
            peft_factors.push(f);
        }
    }
    let meta = serde_json::json!({
        "unet.r": r, "unet.lora_alpha": 8, "unet.use_rslora": false, "unet.rank_pattern": {},
        "unet.alpha_pattern": { special.clone(): 2, "ff.net.2": 16 },
        "unet.target_modules": ["to_q"],
        "text_encoder.r": r, "text_encoder.lora_alpha": 4, "text_encoder.use_rslora": true,
    });
    let peft_path = scratch(&format!("peft-{dtype:?}.safetensors")).join("lora.safetensors");
    write(
        &peft_path,
        &tensors,
        &[("format", "pt".into()), ("lora_adapter_metadata", serde_json::to_string_pretty(&meta).unwrap())],
    );
    (LoraFile::open(&kohya_path).unwrap(), kohya_factors, LoraFile::open(&peft_path).unwrap(), peft_factors)
}

/// Two LoRAs at once (their deltas add where they share weights), then a different set, which
/// must first undo the earlier merge, then a bit-exact restore.
fn two_loras(dtype: Dtype) {
    let nets = tiny_sdxl(dtype);
    let (kohya, kf, peft, pf) = diffusers_pair(&nets, dtype);
    let targets = Targets::sdxl(&nets.unet, &nets.clip_l, &nets.big_g);
    let before = nets.params().map(snapshot);
    let mut both = Expected::new();
    for (fs, s) in [(&kf, 0.7), (&pf, -0.5)] {
        fs.iter().for_each(|f| both.add(nets.params(), f, s));
    }
    let mut only_peft = Expected::new();
    pf.iter().for_each(|f| only_peft.add(nets.params(), f, 1.0));
    assert!(both.values.len() < kf.len() + pf.len(), "the two files should share some weights");

    let mut merger = LoraMerger::new();
    let summary = merger.apply(&targets, &[(&kohya, 0.7), (&peft, -0.5)]).unwrap();
    let counts = |fs: &[Factors]| [0, 1, 2].map(|n| fs.iter().filter(|f| f.net == n).count());
    let got = |i: usize| [summary.loras[i].unet, summary.loras[i].text_encoder_1, summary.loras[i].text_encoder_2];
    assert_eq!((got(0), got(1)), (counts(&kf), counts(&pf)), "{summary}");
    both.check(nets.params(), dtype);
    merger.apply(&targets, &[(&kohya, 0.7)]).unwrap();
    merger.apply(&targets, &[(&peft, 1.0)]).unwrap();
    only_peft.check(nets.params(), dtype);
    merger.restore().unwrap();
    for (b, params) in before.iter().zip(nets.params()) {
        assert_restored(&format!("{dtype:?}"), b, params);
    }
}

#[test]
fn kohya_diffusers_and_peft_together_f32() {
    two_loras(Dtype::F32);
}

#[test]
fn kohya_diffusers_and_peft_together_f16() {
    two_loras(Dtype::F16);
}

/// Older diffusers spellings: attention-processor names (`to_out_lora` = to_out.0, `to_k_lora` =
/// k_proj in the text encoders), `lora_linear_layer`, `.lora.down`, and an `.alpha` tensor.
#[test]
fn old_diffusers_spellings() {
    let dtype = Dtype::F32;
    let nets = tiny_sdxl(dtype);
    let attn = "down_blocks.1.attentions.0.transformer_blocks.0";
    let layer = |i: usize| format!("text_model.encoder.layers.{i}");
    let cases: [(usize, String, String, Option<f32>); 5] = [
        (0, format!("{attn}.attn1.to_q.weight"), format!("unet.{attn}.attn1.processor.to_q_lora"), None),
        (0, format!("{attn}.attn2.to_out.0.weight"), format!("unet.{attn}.attn2.processor.to_out_lora"), None),
        (0, format!("{attn}.ff.net.2.weight"), format!("unet.{attn}.ff.net.2.lora"), Some(2.0)),
        (
            1,
            format!("{}.self_attn.k_proj.weight", layer(0)),
            format!("text_encoder.{}.self_attn.to_k_lora", layer(0)),
            None,
        ),
        (
            2,
            format!("{}.mlp.fc1.weight", layer(1)),
            format!("text_encoder_2.{}.mlp.fc1.lora_linear_layer", layer(1)),
            None,
        ),
    ];
    let (r, strength) = (4, 0.9);
    let mut tensors = Vec::new();
    let mut want = Expected::new();
    for (i, (net, weight, stem, alpha)) in cases.iter().enumerate() {
        let shape = nets.params()[*net].get(weight).unwrap().torch_shape.clone();
        let f = Factors::new(*net, weight, &shape, r, alpha.map_or(1.0, |a| a as f64 / r as f64), 50 + 2 * i as u64);
        // `…lora` stems take `.down.weight`; `…_lora` stems do too (`to_q_lora.down.weight`).
        tensors.push((format!("{stem}.down.weight"), f.down_shape(), f.down.clone()));
        tensors.push((format!("{stem}.up.weight"), f.up_shape(), f.up.clone()));
        if let Some(a) = alpha {
            tensors.push((format!("unet.{attn}.ff.net.2.alpha"), vec![], vec![*a]));
        }
        want.add(nets.params(), &f, strength);
    }
    let path = scratch("old-diffusers.safetensors").join("lora.safetensors");
    write(&path, &tensors, &[]);
    let lora = LoraFile::open(&path).unwrap();
    let before = nets.params().map(snapshot);
    let mut merger = LoraMerger::new();
    let summary =
        merger.apply(&Targets::sdxl(&nets.unet, &nets.clip_l, &nets.big_g), &[(&lora, strength as f32)]).unwrap();
    let s = &summary.loras[0];
    assert_eq!([s.unet, s.text_encoder_1, s.text_encoder_2], [3, 1, 1], "{summary}");
    want.check(nets.params(), dtype);
    merger.restore().unwrap();
    for (b, p) in before.iter().zip(nets.params()) {
        assert_restored("old spellings", b, p);
    }
}
