//! Malformed files never panic. A seeded, bounded fuzzer rewrites safetensors headers (offsets,
//! shapes, ranks, dtypes, lengths) and config files (every key set to an edge value), and
//! everything that reads them must answer with an error or a model, not a panic. The cases it
//! found are kept below as regression tests. `VKDIFF_FUZZ_CASES=N` runs N cases per target
//! instead of the CI default; `VKDIFF_FUZZ_TRACE=1` (with `--nocapture`) prints each case before
//! it runs, to name the one that aborts the process (an allocation failure is not a panic).

use serde_json::{json, Map, Value};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use vkdiff_formats::SafeTensors;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{read_unet_config, unet_checkpoint};
use vkdiff_networks::{
    AutoencoderKl, ClipTextModel, ClipVisionModelWithProjection, ControlNetModel, TextEncoderSlot, UNet,
};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::{ctx, repo, scratch};

/// Something that reads a file and must not panic on it.
type Reader<'a> = dyn Fn(&Path) + 'a;

fn cases(ci_default: usize) -> usize {
    std::env::var("VKDIFF_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(ci_default)
}

/// xorshift64*: the same cases on every machine.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// A safetensors file split into its header and its data.
pub struct Parts {
    pub header: Map<String, Value>,
    pub data: Vec<u8>,
}

pub fn read_parts(path: &Path) -> Parts {
    let bytes = std::fs::read(path).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    Parts { header, data: bytes[8 + n..].to_vec() }
}

pub fn write_parts(path: &Path, parts: &Parts) {
    let header = serde_json::to_vec(&parts.header).unwrap();
    let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
    bytes.extend(header);
    bytes.extend(&parts.data);
    std::fs::write(path, bytes).unwrap();
}

const EDGE_NUMBERS: [f64; 9] = [0.0, 1.0, 2.0, 7.0, -1.0, 4294967295.0, 1.8446744073709552e19, 1e40, 0.5];

fn edge_number(rng: &mut Rng) -> Value {
    let v = *rng.pick(&EDGE_NUMBERS);
    if v.fract() == 0.0 && (0.0..1.8e19).contains(&v) {
        json!(v as u64)
    } else {
        json!(v)
    }
}

/// Any JSON value a broken writer might leave where another was expected.
fn edge_value(rng: &mut Rng) -> Value {
    match rng.below(8) {
        0..=3 => edge_number(rng),
        4 => json!("not a number"),
        5 => Value::Null,
        6 => json!([]),
        _ => json!({}),
    }
}

/// One random change to a tensor entry (or the header), described for the failure report.
fn mutate_header(header: &mut Map<String, Value>, data_len: usize, rng: &mut Rng) -> String {
    let names: Vec<String> = header
        .iter()
        .filter(|(k, v)| *k != "__metadata__" && v.get("data_offsets").is_some())
        .map(|(k, _)| k.clone())
        .collect();
    let name = rng.pick(&names).clone();
    let entry = header.get_mut(&name).unwrap();
    match rng.below(7) {
        0 => {
            let ends = [0, 1, data_len / 2, data_len, data_len + 1, usize::MAX / 2, usize::MAX];
            let (a, b) = (*rng.pick(&ends), *rng.pick(&ends));
            entry["data_offsets"] = json!([a, b]);
            format!("`{name}` data_offsets [{a}, {b}]")
        }
        1 => {
            let other = rng.pick(&names).clone();
            let offsets = header[&other]["data_offsets"].clone();
            header.get_mut(&name).unwrap()["data_offsets"] = offsets.clone();
            format!("`{name}` data_offsets {offsets} as `{other}`'s")
        }
        2 => {
            let rank = rng.below(6);
            let shape: Vec<Value> = (0..rank).map(|_| edge_number(rng)).collect();
            entry["shape"] = json!(shape);
            format!("`{name}` shape {shape:?}")
        }
        3 => {
            // Same element count, other rank: what a wrongly reshaped export holds.
            let numel = entry["shape"]
                .as_array()
                .map_or(1, |s| s.iter().filter_map(Value::as_u64).fold(1u64, u64::saturating_mul));
            let shape = match rng.below(4) {
                0 => json!([numel]),
                1 => json!([]),
                2 => json!([1, numel]),
                _ => json!([numel, 1, 1, 1, 1]),
            };
            entry["shape"] = shape.clone();
            format!("`{name}` reshaped to {shape}")
        }
        4 => {
            let dtype = *rng.pick(&["F64", "I64", "U8", "BOOL", "F8_E4M3", "", "f16"]);
            entry["dtype"] = json!(dtype);
            format!("`{name}` dtype {dtype}")
        }
        5 => {
            let field = *rng.pick(&["dtype", "shape", "data_offsets"]);
            let v = edge_value(rng);
            entry[field] = v.clone();
            format!("`{name}` {field} = {v}")
        }
        _ => {
            let v = edge_value(rng);
            header.insert(name.clone(), v.clone());
            format!("`{name}` = {v}")
        }
    }
}

thread_local!(static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) });

/// Runs `read` on every case; a panic fails the test with the case that caused it.
fn no_panics(cases: &[(String, PathBuf)], read: &dyn Fn(&Path)) {
    // The panics caught here are reported once, below; other threads' panics print as usual.
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.get() {
                default(info)
            }
        }));
    });
    let panicked: Vec<String> = cases
        .iter()
        .filter_map(|(what, path)| {
            QUIET.set(true);
            if std::env::var_os("VKDIFF_FUZZ_TRACE").is_some() {
                eprintln!("case: {what}");
            }
            let outcome = catch_unwind(AssertUnwindSafe(|| read(path)));
            QUIET.set(false);
            outcome.err().map(|e| {
                let message = e
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                format!("{what} ({}): {message}", path.display())
            })
        })
        .collect();
    assert!(panicked.is_empty(), "{} of {} cases panicked:\n{}", panicked.len(), cases.len(), panicked.join("\n"));
}

/// Everything that reads a safetensors file without a device.
fn read_tensor_file(path: &Path) {
    if let Ok(file) = SafeTensors::open(path) {
        for name in file.entries.keys() {
            let _ = file.values(name);
        }
    }
    let _ = read_unet_config(path);
    let _ = AutoencoderKl::sdxl_config(path);
    let _ = ClipTextModel::sdxl_config(path, TextEncoderSlot::ClipL);
    let _ = ClipTextModel::sdxl_config(path, TextEncoderSlot::BigG);
    let _ = LoraFile::open(path);
}

#[test]
fn fuzzed_safetensors_headers_never_panic() {
    let dir = scratch("headers");
    let sources = [
        "tests/fixtures/unet/heads/sd_xl_single_file.safetensors",
        "tests/fixtures/workflow/lora-peft.safetensors",
        "tests/fixtures/workflow/lora-kohya-ldm.safetensors",
    ];
    let mut rng = Rng(0x5eed_0001);
    let mut all = Vec::new();
    for (s, source) in sources.iter().enumerate() {
        let parts = read_parts(&repo(source));
        for i in 0..cases(300) {
            let mut header = parts.header.clone();
            let what = (0..1 + rng.below(2))
                .map(|_| mutate_header(&mut header, parts.data.len(), &mut rng))
                .collect::<Vec<_>>()
                .join("; ");
            let path = dir.join(format!("{s}-{i}.safetensors"));
            write_parts(&path, &Parts { header, data: parts.data.clone() });
            all.push((format!("{source}: {what}"), path));
        }
    }
    no_panics(&all, &read_tensor_file);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn damaged_bytes_never_panic() {
    let dir = scratch("bytes");
    let bytes = std::fs::read(repo("tests/fixtures/workflow/lora-peft.safetensors")).unwrap();
    let header_end = 8 + u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let mut rng = Rng(0x5eed_0002);
    let mut all = Vec::new();
    for i in 0..cases(300) {
        let mut b = bytes.clone();
        let what = match rng.below(3) {
            0 => {
                let at = rng.below(header_end);
                b[at] = rng.next() as u8;
                format!("header byte {at} changed")
            }
            1 => {
                let len = *rng.pick(&[0u64, 1, 7, header_end as u64, u64::MAX, u64::MAX / 2]);
                b[..8].copy_from_slice(&len.to_le_bytes());
                format!("header length {len}")
            }
            _ => {
                let at = rng.below(b.len());
                b.truncate(at);
                format!("cut at byte {at}")
            }
        };
        let path = dir.join(format!("{i}.safetensors"));
        std::fs::write(&path, b).unwrap();
        all.push((what, path));
    }
    no_panics(&all, &read_tensor_file);
    std::fs::remove_dir_all(dir).unwrap();
}

/// A model folder whose weights are links to a fixture's and whose `component/config.json` is
/// `config`.
fn folder_with_config(dir: &Path, source: &Path, component: &str, config: &Value) {
    for entry in std::fs::read_dir(source).unwrap() {
        let entry = entry.unwrap();
        let target = dir.join(entry.file_name());
        if entry.file_name() != component {
            std::os::unix::fs::symlink(entry.path(), target).unwrap();
            continue;
        }
        std::fs::create_dir_all(&target).unwrap();
        for file in std::fs::read_dir(entry.path()).unwrap() {
            let file = file.unwrap();
            if file.file_name() != "config.json" {
                std::os::unix::fs::symlink(file.path(), target.join(file.file_name())).unwrap();
            }
        }
        std::fs::write(target.join("config.json"), serde_json::to_vec(config).unwrap()).unwrap();
    }
}

/// `config` with one key (or one element of an array) set to an edge value.
fn mutate_config(config: &Value, rng: &mut Rng) -> (Value, String) {
    let mut config = config.clone();
    let map = config.as_object_mut().unwrap();
    let keys: Vec<String> = map.keys().cloned().collect();
    let key = rng.pick(&keys).clone();
    let new = match &map[&key] {
        Value::Array(items) if !items.is_empty() && rng.below(2) == 0 => {
            let mut items = items.clone();
            let i = rng.below(items.len());
            items[i] = edge_value(rng);
            Value::Array(items)
        }
        Value::String(_) if rng.below(2) == 0 => json!(*rng.pick(&["", "bogus", "silu", "gelu"])),
        _ => edge_value(rng),
    };
    let what = format!("{key} = {new}");
    map.insert(key, new);
    (config, what)
}

#[test]
fn fuzzed_config_files_never_panic() {
    let ctx = ctx();
    let tiny = repo("tests/fixtures/pipeline/tiny-sdxl");
    let unet = read_unet_config(&tiny).unwrap();
    let workflow = repo("tests/fixtures/workflow");
    let targets: [(&Path, &str, &Reader<'_>); 6] = [
        (&tiny, "unet", &|p| drop(unet_checkpoint(&ctx, p, Dtype::F16).and_then(|(c, ckpt)| UNet::load(&c, &ckpt)))),
        (&tiny, "vae", &|p| drop(AutoencoderKl::load_sdxl(&ctx, p, Dtype::F16))),
        (&tiny, "text_encoder", &|p| drop(ClipTextModel::load_sdxl(&ctx, p, TextEncoderSlot::ClipL, Dtype::F16))),
        (&tiny, "text_encoder_2", &|p| drop(ClipTextModel::load_sdxl(&ctx, p, TextEncoderSlot::BigG, Dtype::F16))),
        (&workflow, "image_encoder", &|p| {
            drop(ClipVisionModelWithProjection::load_folder(&ctx, &p.join("image_encoder"), Dtype::F16))
        }),
        (&workflow, "controlnet", &|p| drop(ControlNetModel::load(&ctx, &p.join("controlnet"), &unet, Dtype::F16))),
    ];
    let mut rng = Rng(0x5eed_0003);
    for (source, component, load) in targets {
        let dir = scratch(&format!("config-{component}"));
        let original: Value =
            serde_json::from_slice(&std::fs::read(source.join(component).join("config.json")).unwrap()).unwrap();
        let mut all = Vec::new();
        for i in 0..cases(40) {
            let (config, what) = mutate_config(&original, &mut rng);
            let case = dir.join(i.to_string());
            std::fs::create_dir_all(&case).unwrap();
            folder_with_config(&case, source, component, &config);
            all.push((format!("{component}/config.json: {what}"), case));
        }
        no_panics(&all, load);
        std::fs::remove_dir_all(dir).unwrap();
    }
}

// Cases the fuzzer found, each now one clear error.

fn error_of<T>(result: vkdiff_networks::Result<T>) -> String {
    match result {
        Ok(_) => panic!("a malformed file was accepted"),
        Err(e) => e.to_string(),
    }
}

/// A copy of `source` with its header changed by `change`.
fn rewritten(name: &str, source: &str, change: impl FnOnce(&mut Map<String, Value>)) -> PathBuf {
    let mut parts = read_parts(&repo(source));
    change(&mut parts.header);
    let path = scratch(name).join("model.safetensors");
    write_parts(&path, &parts);
    path
}

#[test]
fn a_single_file_weight_of_too_low_a_rank_is_named() {
    let path = rewritten("rank", "tests/fixtures/unet/heads/sd_xl_single_file.safetensors", |h| {
        h["model.diffusion_model.input_blocks.0.0.weight"]["shape"] = json!([1152]);
    });
    let err = error_of(read_unet_config(&path));
    crate::errors::assert_one_line(&err, &["input_blocks.0.0.weight", "[1152]"]);
}

#[test]
fn overlapping_or_overflowing_tensors_are_refused() {
    let source = "tests/fixtures/workflow/lora-peft.safetensors";
    let first = |h: &Map<String, Value>| h.iter().find(|(k, _)| *k != "__metadata__").map(|(k, _)| k.clone()).unwrap();
    let path = rewritten("overlap", source, |h| {
        // Two tensors of one size, the second pointed at the first's bytes.
        let len = |v: &Value| v["data_offsets"][1].as_u64().unwrap() - v["data_offsets"][0].as_u64().unwrap();
        let tensors: Vec<(&String, &Value)> = h.iter().filter(|(k, _)| *k != "__metadata__").collect();
        let (a, b) = tensors
            .iter()
            .flat_map(|a| tensors.iter().map(move |b| (a, b)))
            .find(|(a, b)| a.0 != b.0 && len(a.1) == len(b.1))
            .unwrap();
        let (a, b) = (a.0.clone(), b.0.clone());
        h[&b]["data_offsets"] = h[&a]["data_offsets"].clone();
    });
    crate::errors::assert_one_line(&error_of(SafeTensors::open(&path).map_err(Into::into)), &["overlaps"]);
    let path = rewritten("overflow", source, |h| {
        let name = first(h);
        h[&name]["shape"] = json!([4294967296u64, 4294967296u64, 4]);
    });
    crate::errors::assert_one_line(&error_of(SafeTensors::open(&path).map_err(Into::into)), &["too large"]);
}

#[test]
fn norm_groups_of_zero_and_absurd_widths_are_config_errors() {
    let ctx = ctx();
    let tiny = repo("tests/fixtures/pipeline/tiny-sdxl");
    let original: Value = serde_json::from_slice(&std::fs::read(tiny.join("unet/config.json")).unwrap()).unwrap();
    for (key, value, wants) in
        [("norm_num_groups", json!(0), "norm_num_groups"), ("cross_attention_dim", json!(4294967295u64), "shape")]
    {
        let dir = scratch(&format!("config-{key}"));
        let mut config = original.clone();
        config[key] = value;
        folder_with_config(&dir, &tiny, "unet", &config);
        let err = error_of(unet_checkpoint(&ctx, &dir, Dtype::F16).and_then(|(c, ckpt)| UNet::load(&c, &ckpt)));
        crate::errors::assert_one_line(&err, &[wants]);
    }
}

#[test]
fn a_peft_alpha_of_the_wrong_type_is_refused_not_replaced() {
    let path = rewritten("alpha", "tests/fixtures/workflow/lora-peft.safetensors", |h| {
        let meta = h["__metadata__"]["lora_adapter_metadata"].as_str().unwrap();
        let mut config: Value = serde_json::from_str(meta).unwrap();
        config["unet.lora_alpha"] = json!("16");
        h["__metadata__"]["lora_adapter_metadata"] = json!(config.to_string());
    });
    let err = match LoraFile::open(&path) {
        Ok(_) => panic!("a string lora_alpha was accepted"),
        Err(e) => e.to_string(),
    };
    crate::errors::assert_one_line(&err, &["unet.lora_alpha", "\"16\"", "not a number"]);
}
