//! Compiles every kernel variant listed in `src/spec.rs` from WGSL to SPIR-V with naga, validating
//! each one; a broken kernel fails the build with the WGSL file and line.

use std::{env, fmt::Write as _, fs, path::Path, process::exit};

include!("src/spec.rs");

/// A kernel's source: a one-line prelude followed by its files, with where each file starts.
struct Source {
    text: String,
    /// (first line in `text`, file name), in order.
    files: Vec<(usize, &'static str)>,
}

impl Source {
    fn new(spec: &KernelSpec, dtype: Dtype, params: &[(&str, u32)]) -> Source {
        let mut text = match dtype {
            Dtype::F16 => String::from("enable f16; alias S = f16;"),
            Dtype::F32 => String::from("alias S = f32;"),
        };
        for (name, value) in params {
            write!(text, " const {name}: u32 = {value}u;").unwrap();
        }
        text.push('\n');
        let mut files = Vec::new();
        let mut line = 2;
        for file in spec.files {
            let path = Path::new("wgsl").join(file);
            let body = fs::read_to_string(&path)
                .unwrap_or_else(|e| fail(&format!("{}: {e}", path.display())));
            files.push((line, *file));
            line += body.lines().count();
            text.push_str(&body);
            if !body.ends_with('\n') {
                text.push('\n');
            }
        }
        Source { text, files }
    }

    /// Maps a 1-based line of the concatenated text back to `file:line`.
    fn locate(&self, line: usize) -> String {
        match self.files.iter().rev().find(|(start, _)| *start <= line) {
            Some((start, file)) => format!("kernels/wgsl/{file}:{}", line - start + 1),
            None => "kernels/src/spec.rs (generated prelude)".into(),
        }
    }
}

fn fail(message: &str) -> ! {
    for line in message.lines() {
        println!("cargo::error={line}");
    }
    exit(1)
}

/// Expands `// #unroll NAME COUNT` … `// #end` blocks: the body repeated COUNT times (a number
/// or a parameter) with the whole word NAME replaced by `0u`, `1u`, …. The Vulkan drivers we
/// target do not unroll loops over register arrays (lavapipe spills them to memory), so hot
/// loops are unrolled here. Innermost blocks go first, and each expansion is written on one
/// line followed by blank ones, so error lines still point into the file.
fn unroll(text: &str, params: &[(&str, u32)]) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let is = |i: usize, tag: &str| lines[i].trim_start().starts_with(tag);
    let Some(end) = (0..lines.len()).find(|&i| is(i, "// #end")) else {
        return text.to_string();
    };
    let start = (0..end)
        .rev()
        .find(|&i| is(i, "// #unroll "))
        .unwrap_or_else(|| fail(&format!("`// #end` without `// #unroll` at generated line {}", end + 1)));
    let words: Vec<&str> = lines[start].split_whitespace().collect();
    let (name, count) = (words[2], words[3]);
    let count: u32 = count
        .parse()
        .ok()
        .or_else(|| params.iter().find(|(p, _)| *p == count).map(|(_, v)| *v))
        .unwrap_or_else(|| fail(&format!("`// #unroll {name} {count}`: count is neither a number nor a parameter")));
    // Comments would swallow the rest of the joined line.
    let body: Vec<&str> = lines[start + 1..end].iter().map(|l| l.split("//").next().unwrap()).collect();
    let body = body.join(" ");
    let copies: Vec<String> = (0..count).map(|i| replace_word(&body, name, &format!("{i}u"))).collect();
    let mut out: Vec<String> = lines[..start].iter().map(|s| s.to_string()).collect();
    out.push(copies.join(" "));
    out.extend(std::iter::repeat_n(String::new(), end - start));
    out.extend(lines[end + 1..].iter().map(|s| s.to_string()));
    unroll(&out.join("\n"), params)
}

/// Replaces whole-word occurrences of `word` (identifier boundaries) in `text`.
fn replace_word(text: &str, word: &str, with: &str) -> String {
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find(word) {
        let before = rest[..i].chars().next_back();
        let after = rest[i + word.len()..].chars().next();
        out.push_str(&rest[..i]);
        if before.is_some_and(is_ident) || after.is_some_and(is_ident) {
            out.push_str(word);
        } else {
            out.push_str(with);
        }
        rest = &rest[i + word.len()..];
    }
    out.push_str(rest);
    out
}

fn compile(spec: &KernelSpec, dtype: Dtype, params: &[(&str, u32)]) -> Vec<u32> {
    use naga::{back::spv, valid};
    let mut src = Source::new(spec, dtype, params);
    src.text = unroll(&src.text, params);
    let what = format!("kernel `{}` ({dtype:?}, {params:?})", spec.name);
    let module = naga::front::wgsl::parse_str(&src.text).unwrap_or_else(|e| {
        let at = e.location(&src.text).map(|l| src.locate(l.line_number as usize));
        fail(&format!("{}: {what}: {}\n{}", at.unwrap_or_default(), e.message(), e.emit_to_string(&src.text)))
    });
    let caps = valid::Capabilities::IMMEDIATES | valid::Capabilities::SHADER_FLOAT16 | valid::Capabilities::SUBGROUP;
    let info = valid::Validator::new(valid::ValidationFlags::all(), caps)
        .subgroup_stages(valid::ShaderStages::COMPUTE)
        .subgroup_operations(valid::SubgroupOperationSet::all())
        .validate(&module)
        .unwrap_or_else(|e| {
            let at = e.spans().next().map(|(span, _)| src.locate(span.location(&src.text).line_number as usize));
            fail(&format!("{}: {what}: {}\n{}", at.unwrap_or_default(), e.as_inner(), e.emit_to_string(&src.text)))
        });
    let options = spv::Options {
        lang_version: (1, 3),
        flags: spv::WriterFlags::empty(),
        zero_initialize_workgroup_memory: spv::ZeroInitializeWorkgroupMemoryMode::Native,
        use_storage_input_output_16: false,
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: naga::proc::BoundsCheckPolicy::Restrict,
            buffer: naga::proc::BoundsCheckPolicy::Restrict,
            image_load: naga::proc::BoundsCheckPolicy::Restrict,
            binding_array: naga::proc::BoundsCheckPolicy::Restrict,
        },
        ..Default::default()
    };
    let pipeline = spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: "main".into() };
    spv::write_vec(&module, &info, &options, Some(&pipeline))
        .unwrap_or_else(|e| fail(&format!("kernels/wgsl/{}: {what}: SPIR-V output: {e}", spec.files.last().unwrap())))
}

fn main() {
    println!("cargo::rerun-if-changed=src/spec.rs");
    println!("cargo::rerun-if-changed=wgsl");
    let out = env::var("OUT_DIR").unwrap();
    let mut table = String::from("pub static VARIANTS: &[Variant] = &[\n");
    for spec in KERNELS {
        for dtype in [Dtype::F32, Dtype::F16] {
            for (i, params) in spec.params.iter().enumerate() {
                let words = compile(spec, dtype, params);
                let file = format!("{}.{dtype:?}.{i}.spv", spec.name);
                let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
                fs::write(Path::new(&out).join(&file), bytes).unwrap();
                writeln!(
                    table,
                    "    Variant {{ kernel: {:?}, dtype: Dtype::{dtype:?}, params: &{params:?}, spirv: include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{file}\")) }},",
                    spec.name
                )
                .unwrap();
            }
        }
    }
    table.push_str("];\n");
    fs::write(Path::new(&out).join("variants.rs"), table).unwrap();
}
