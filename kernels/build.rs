//! Compiles every kernel variant listed in `src/spec.rs` and `src/spec_cooperative.rs` from WGSL to SPIR-V with naga, validating
//! each one; a broken kernel fails the build with the WGSL file and line.

use std::{env, fmt::Write as _, fs, path::Path, process::exit};

include!("src/spec.rs");
include!("src/spec_cooperative.rs");
include!("compile.rs");

fn fail(message: &str) -> ! {
    for line in message.lines() {
        println!("cargo::error={line}");
    }
    exit(1)
}

/// The kernel's files, read from `wgsl/`.
fn read_files(spec: &KernelSpec) -> Vec<(String, String)> {
    spec.files
        .iter()
        .map(|file| {
            let path = Path::new("wgsl").join(file);
            let body = fs::read_to_string(&path).unwrap_or_else(|e| fail(&format!("{}: {e}", path.display())));
            (file.to_string(), body)
        })
        .collect()
}

/// `files` with B read from texels (b_texels.wgsl) where they read it from storage.
fn texel_b_files(files: &[(String, String)]) -> Vec<(String, String)> {
    let texels = fs::read_to_string(Path::new("wgsl").join("b_texels.wgsl"))
        .unwrap_or_else(|e| fail(&format!("wgsl/b_texels.wgsl: {e}")));
    files
        .iter()
        .map(|(name, body)| match name.as_str() {
            "b_units.wgsl" => ("b_texels.wgsl".to_string(), texels.clone()),
            _ => (name.clone(), body.clone()),
        })
        .collect()
}

fn main() {
    println!("cargo::rerun-if-changed=src/spec.rs");
    println!("cargo::rerun-if-changed=src/spec_cooperative.rs");
    println!("cargo::rerun-if-changed=compile.rs");
    println!("cargo::rerun-if-changed=spirv_rewrite.rs");
    println!("cargo::rerun-if-changed=spirv_texels.rs");
    println!("cargo::rerun-if-changed=wgsl");
    let out = env::var("OUT_DIR").unwrap();
    let mut table = String::from("pub static VARIANTS: &[Variant] = &[\n");
    let scalar = KERNELS.iter().flat_map(|spec| [(spec, Dtype::F32, false), (spec, Dtype::F16, false)]);
    let cooperative = COOPERATIVE_KERNELS.iter().map(|spec| (spec, Dtype::F16, true));
    for (spec, dtype, cooperative) in scalar.chain(cooperative) {
        let target = if cooperative || GPU_KERNELS.contains(&spec.name) { Target::Gpu } else { Target::Any };
        let files = read_files(spec);
        // Each reading of the operands a kernel is built for: as 32- and 64-bit words (WD), B
        // from storage and from texels (TB).
        let words: &[u32] = if WORD_LOADS.contains(&spec.name) { &[0, 1] } else { &[] };
        let texels: &[u32] = if TEXEL_B.contains(&spec.name) { &[0, 1] } else { &[] };
        let all = spec.params.iter().flat_map(|params| {
            let with = |name: &'static str, values: &[u32], sets: Vec<Vec<(&'static str, u32)>>| match values {
                [] => sets,
                _ => sets.iter().flat_map(|set| values.iter().map(|&x| [&set[..], &[(name, x)]].concat())).collect(),
            };
            with("TB", texels, with("WD", words, vec![params.to_vec()]))
        });
        let texel_files = if texels.is_empty() { Vec::new() } else { texel_b_files(&files) };
        for (i, params) in all.enumerate() {
            let params = &params[..];
            let files = if params.contains(&("TB", 1)) { &texel_files } else { &files };
            let src = Source::new(&prelude(dtype == Dtype::F16, params, cooperative), files);
            let what = format!("kernel `{}` ({dtype:?}, {params:?})", spec.name);
            let words = compile(src, params, (cooperative, target), &what).unwrap_or_else(|e| fail(&e));
            let file = format!("{}.{dtype:?}.{i}.spv", spec.name);
            let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
            fs::write(Path::new(&out).join(&file), bytes).unwrap();
            writeln!(
                table,
                "    Variant {{ kernel: {:?}, dtype: Dtype::{dtype:?}, params: &{params:?}, \
                    spirv: include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{file}\")) }},",
                spec.name
            )
            .unwrap();
        }
    }
    table.push_str("];\n");
    fs::write(Path::new(&out).join("variants.rs"), table).unwrap();
}
