//! Compiles every kernel variant listed in `src/spec.rs` and `src/spec_cooperative.rs` from WGSL to SPIR-V with naga, validating
//! each one; a broken kernel fails the build with the WGSL file and line.

use std::{env, fmt::Write as _, fs, path::Path, process::exit};

include!("src/spec.rs");
include!("src/spec_cooperative.rs");
include!("src/spirv_words.rs");
include!("compile.rs");

fn fail(message: &str) -> ! {
    for line in message.lines() {
        println!("cargo::error={line}");
    }
    exit(1)
}

/// `wgsl/name`, as (name, text).
fn read(name: &str) -> (String, String) {
    let path = Path::new("wgsl").join(name);
    (name.to_string(), fs::read_to_string(&path).unwrap_or_else(|e| fail(&format!("{}: {e}", path.display()))))
}

/// The files a TB = 1 variant reads in place of others (see [`texel_files`]), read once.
const TEXEL_FILES: [&str; 3] = ["a_texels.wgsl", "b_texels.wgsl", "gemm_sg_pairs.wgsl"];

/// What a TB = 1 variant reads from texels, and its files: B always (b_texels.wgsl in place of
/// b_units.wgsl). A too (TA = 1) where the kernel reads A as a plain matrix (a_matrix_v4.wgsl):
/// in f32 as four-value texels (a_texels.wgsl), in f16 where B is stored N×K and a turn has
/// pairs of steps as eight-half texels of both (gemm_sg_pairs.wgsl); other f16 variants read B
/// only.
fn texel_files(
    files: &[(String, String)],
    texel_sources: &[(String, String)],
    f16: bool,
    params: &[(&str, u32)],
) -> (Vec<(String, String)>, bool) {
    let texel_file = |name: &str| texel_sources.iter().find(|(n, _)| n == name).expect("in TEXEL_FILES").clone();
    let plain_a = files.iter().any(|(name, _)| name == "a_matrix_v4.wgsl");
    let steps_in_pairs = params.iter().any(|&(p, v)| p == "KS" && v % 2 == 0);
    let pairs = f16 && plain_a && params.contains(&("BT", 1)) && steps_in_pairs;
    let texel_a = plain_a && (pairs || !f16);
    let texels: Vec<(String, String)> = files
        .iter()
        .filter_map(|(name, body)| match name.as_str() {
            "a_as_f32.wgsl" if texel_a => None,
            "a_matrix_v4.wgsl" if pairs => None,
            "a_matrix_v4.wgsl" if texel_a => Some(texel_file("a_texels.wgsl")),
            "b_units.wgsl" if pairs => None,
            "b_units.wgsl" => Some(texel_file("b_texels.wgsl")),
            "gemm_sg_steps.wgsl" if pairs => Some(texel_file("gemm_sg_pairs.wgsl")),
            _ => Some((name.clone(), body.clone())),
        })
        .collect();
    (texels, texel_a)
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
    let texel_sources = TEXEL_FILES.map(read);
    let scalar = KERNELS.iter().flat_map(|spec| [(spec, Dtype::F32, false), (spec, Dtype::F16, false)]);
    let cooperative = COOPERATIVE_KERNELS.iter().map(|spec| (spec, Dtype::F16, true));
    for (spec, dtype, cooperative) in scalar.chain(cooperative) {
        let target = if cooperative || GPU_KERNELS.contains(&spec.name) { Target::Gpu } else { Target::Any };
        let files: Vec<(String, String)> = spec.files.iter().map(|file| read(file)).collect();
        // Each reading of the operands a kernel is built for: as 32- and 64-bit words (WD), B
        // (and where it can, A: TA) from storage and from texels (TB).
        let words: &[u32] = if WORD_LOADS.contains(&spec.name) { &[0, 1] } else { &[] };
        let texels: &[u32] = if TEXEL_B.contains(&spec.name) { &[0, 1] } else { &[] };
        let all = spec.params.iter().flat_map(|params| {
            let with = |name: &'static str, values: &[u32], sets: Vec<Vec<(&'static str, u32)>>| match values {
                [] => sets,
                _ => sets.iter().flat_map(|set| values.iter().map(|&x| [&set[..], &[(name, x)]].concat())).collect(),
            };
            with("TB", texels, with("WD", words, vec![params.to_vec()]))
        });
        for (i, params) in all.enumerate() {
            let (files, params) = match params.contains(&("TB", 1)) {
                true => match texel_files(&files, &texel_sources, dtype == Dtype::F16, &params) {
                    (texels, true) => (texels, [&params[..], &[("TA", 1)]].concat()),
                    (texels, false) => (texels, params),
                },
                false => (files.clone(), params),
            };
            let (files, params) = (&files, &params[..]);
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
