// WGSL → SPIR-V for one kernel variant: concatenation with a prelude, `// #unroll` expansion,
// naga parsing, validation and SPIR-V output, with errors mapped back to `file:line`.
// Included by build.rs (which compiles every variant) and by the crate's tests.

/// A kernel's source: a one-line prelude followed by its files, with where each file starts.
struct Source {
    text: String,
    /// (first line in `text`, file name), in order.
    files: Vec<(usize, String)>,
}

impl Source {
    /// `prelude` (one line) followed by each `(file name, text)`.
    fn new(prelude: &str, files: &[(String, String)]) -> Source {
        let mut text = format!("{prelude}\n");
        let mut starts = Vec::new();
        let mut line = 2;
        for (name, body) in files {
            starts.push((line, name.clone()));
            line += body.lines().count();
            text.push_str(body);
            if !body.ends_with('\n') {
                text.push('\n');
            }
        }
        Source { text, files: starts }
    }

    /// Maps a 1-based line of the concatenated text back to `file:line`.
    fn locate(&self, line: usize) -> String {
        match self.files.iter().rev().find(|(start, _)| *start <= line) {
            Some((start, file)) => format!("kernels/wgsl/{file}:{}", line - start + 1),
            None => "kernels/src/spec.rs (generated prelude)".into(),
        }
    }
}

/// The prelude of a variant: the storage type `S` and the parameters as constants; for
/// cooperative kernels also the fragment types FA, FB (f16 operands) and FC (f32 accumulator)
/// of the variant's CM×CM shape.
fn prelude(f16: bool, params: &[(&str, u32)], cooperative: bool) -> String {
    let mut text = String::from(match (f16, cooperative) {
        (_, true) => "enable f16; enable wgpu_cooperative_matrix; alias S = f16;",
        (true, false) => "enable f16; alias S = f16;",
        (false, false) => "alias S = f32;",
    });
    for (name, value) in params {
        text.push_str(&format!(" const {name}: u32 = {value}u;"));
    }
    if let Some((_, cm)) = params.iter().find(|(name, _)| *name == "CM") {
        for (alias, scalar, role) in [("FA", "f16", "A"), ("FB", "f16", "B"), ("FC", "f32", "C")] {
            text.push_str(&format!(" alias {alias} = coop_mat{cm}x{cm}<{scalar}, {role}>;"));
        }
    }
    text
}

/// Expands `// #unroll NAME COUNT` … `// #end` blocks: the body repeated COUNT times (a number
/// or a parameter) with the whole word NAME replaced by `0u`, `1u`, …. The Vulkan drivers we
/// target do not unroll loops over register arrays (lavapipe spills them to memory), so hot
/// loops are unrolled here. Innermost blocks go first, and each expansion is written on one
/// line followed by blank ones, so error lines still point into the file.
fn unroll(text: &str, params: &[(&str, u32)]) -> Result<String, String> {
    let lines: Vec<&str> = text.lines().collect();
    let is = |i: usize, tag: &str| lines[i].trim_start().starts_with(tag);
    let Some(end) = (0..lines.len()).find(|&i| is(i, "// #end")) else {
        return Ok(text.to_string());
    };
    let start = (0..end)
        .rev()
        .find(|&i| is(i, "// #unroll "))
        .ok_or_else(|| format!("line {}: `// #end` without `// #unroll`", end + 1))?;
    let words: Vec<&str> = lines[start].split_whitespace().collect();
    let (name, count) = (words.get(2).copied().unwrap_or(""), words.get(3).copied().unwrap_or(""));
    let count = unroll_count(count, params).ok_or_else(|| {
        format!(
            "line {}: `// #unroll {name} {count}`: count is not numbers and parameters joined by * and /",
            start + 1
        )
    })?;
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

/// The value of an unroll count: numbers and parameters joined by `*` and `/`, left to right
/// (`2*CM*CM/SG`); None for anything else or a division that leaves a remainder.
fn unroll_count(text: &str, params: &[(&str, u32)]) -> Option<u32> {
    let value = |word: &str| word.parse().ok().or_else(|| params.iter().find(|(p, _)| *p == word).map(|(_, v)| *v));
    let mut words = text.split_inclusive(['*', '/']);
    let first = words.next()?;
    let (mut acc, mut op) = (value(first.trim_end_matches(['*', '/']))?, first.chars().last()?);
    for word in words {
        let x = value(word.trim_end_matches(['*', '/']))?;
        acc = match op {
            '*' => acc.checked_mul(x)?,
            '/' if x != 0 && acc % x == 0 => acc / x,
            _ => return None,
        };
        op = word.chars().last()?;
    }
    (!matches!(op, '*' | '/')).then_some(acc)
}

/// Replaces whole-word occurrences of `word` (identifier boundaries) in `text`.
fn replace_word(text: &str, word: &str, with: &str) -> String {
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find(word) {
        out.push_str(&rest[..i]);
        // The character before the match may already be in `out` (an earlier match).
        let before = out.chars().next_back();
        let after = rest[i + word.len()..].chars().next();
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

/// SPIR-V words for `src`; on failure one message starting with `file:line: what: `, followed
/// by naga's rendering of the error.
fn compile(mut src: Source, params: &[(&str, u32)], cooperative: bool, what: &str) -> Result<Vec<u32>, String> {
    use naga::{back::spv, valid};
    src.text = unroll(&src.text, params).map_err(|e| format!("{what}: {e}"))?;
    let module = naga::front::wgsl::parse_str(&src.text).map_err(|e| {
        let at = e.location(&src.text).map(|l| src.locate(l.line_number as usize));
        format!("{}: {what}: {}\n{}", at.unwrap_or_default(), e.message(), e.emit_to_string(&src.text))
    })?;
    let mut caps = valid::Capabilities::IMMEDIATES | valid::Capabilities::SHADER_FLOAT16 | valid::Capabilities::SUBGROUP;
    caps.set(valid::Capabilities::COOPERATIVE_MATRIX, cooperative);
    let info = valid::Validator::new(valid::ValidationFlags::all(), caps)
        .subgroup_stages(valid::ShaderStages::COMPUTE)
        .subgroup_operations(valid::SubgroupOperationSet::all())
        .validate(&module)
        .map_err(|e| {
            let at = e.spans().next().map(|(span, _)| src.locate(span.location(&src.text).line_number as usize));
            format!("{}: {what}: {}\n{}", at.unwrap_or_default(), e.as_inner(), e.emit_to_string(&src.text))
        })?;
    // Measured with naga 30 on lavapipe: SPIR-V 1.3 for subgroups, native workgroup zero-init (the polyfill costs
    // seconds of JIT on lavapipe), no StorageInputOutput16 (lavapipe lacks it), Restrict bounds.
    let restrict = naga::proc::BoundsCheckPolicy::Restrict;
    let options = spv::Options {
        lang_version: (1, 3),
        flags: spv::WriterFlags::empty(),
        zero_initialize_workgroup_memory: spv::ZeroInitializeWorkgroupMemoryMode::Native,
        use_storage_input_output_16: false,
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: restrict,
            buffer: restrict,
            image_load: restrict,
            binding_array: restrict,
        },
        ..Default::default()
    };
    let pipeline = spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: "main".into() };
    spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| format!("{what}: SPIR-V output: {e}"))
}
