// WGSL → SPIR-V for one kernel variant: concatenation with a prelude, `// #unroll` expansion,
// naga parsing, validation and SPIR-V output, with errors mapped back to `file:line`.
// Included by build.rs (which compiles every variant) and by the crate's tests.

include!("spirv_rewrite.rs");
include!("spirv_texels.rs");

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

/// The prelude of a variant: the storage type `S`, the parameters as constants, `UW` (the
/// values in a unit, what the vec4 loaders read at once: a parameter of the matrix-unit GEMM and
/// convolution, 4 elsewhere) and `Unit`, such a unit as kernels move it; for cooperative
/// kernels also the fragment types FA (f16, FM×FK), FB (f16, FK×FN) and FC (f32 accumulator,
/// FM×FN).
///
/// Cooperative kernels move f16 data as its bits, `Unit` = `vec2<u32>` or `vec4<u32>` (UW = 8,
/// 16-byte loads), and hold it in workgroup memory as `Words`, `vec2<f32>` or `vec4<f32>`: as
/// `vec4<f16>`, NIR splits a unit into halves that the compilers then shuffle (AMD's ACO 4 moves
/// a unit, NVIDIA's NAK 6 byte permutes). naga 30 types a cooperative load by the pointer it
/// reads through and knows f16 and f32 fragments only, so FA and FB are declared f32 here, and
/// the SPIR-V makes them f16 (SPV_KHR_cooperative_matrix lets a load's pointee differ from the
/// fragment's component type). naga also spells only square 8×8 and 16×16 fragments, so all three
/// are declared 8×8 and given the variant's shape in the SPIR-V ([`shape_fragments`]).
fn prelude(f16: bool, params: &[(&str, u32)], cooperative: bool) -> String {
    let mut text = String::from(match (f16, cooperative) {
        (_, true) => "enable f16; enable wgpu_cooperative_matrix; alias S = f16;",
        (true, false) => "enable f16; alias S = f16;",
        (false, false) => "alias S = f32;",
    });
    if !cooperative {
        let lanes = params.iter().find(|(name, _)| *name == "SG").map_or(0, |(_, value)| *value);
        let words = params.iter().find(|(name, _)| *name == "WD").map(|(_, value)| *value);
        text.push_str(scalar_unit(f16, words, lanes));
    }
    for (name, value) in params {
        text.push_str(&format!(" const {name}: u32 = {value}u;"));
    }
    let uw = params.iter().find(|(name, _)| *name == "UW").map(|(_, value)| *value);
    if uw.is_none() {
        text.push_str(" const UW: u32 = 4u;");
    }
    if cooperative {
        let words = uw.unwrap_or(4) / 2;
        text.push_str(&format!(" alias Unit = vec{words}<u32>; alias Words = vec{words}<f32>;"));
        for (alias, role) in [("FA", "A"), ("FB", "B"), ("FC", "C")] {
            text.push_str(&format!(" alias {alias} = coop_mat8x8<f32, {role}>;"));
        }
    }
    text
}

/// `Unit`, `unit_f32` (a unit widened to f32) and `f32_unit` (four f32 values narrowed to a
/// unit, for stores), for the kernels that are not cooperative.
/// The kernels of [`WORD_LOADS`] read their units as words, `words` = WD at `lanes` lanes:
/// - WD = 1, 64-bit words up to [`WIDEST_64_BIT_WORDS`] lanes: lavapipe before Mesa 26 loads a
///   storage buffer one component at a time, each a loop of branches over the lanes, so 64-bit
///   components take a quarter of the loops of f16 ones and half of f32 ones
///   (docs/benchmark-log.md, "64-bit words"). Wider, WD = 1 reads 32-bit words as WD = 0 does.
/// - WD = 0, 32-bit words: an f16 unit is two `u32`s, not four halves, which Mesa 26.1's
///   lavapipe gathers 1.2–1.5× faster (docs/benchmark-log.md, "32-bit words"); an f32 unit is
///   read as it is.
///
/// Every other kernel reads its units as declared.
fn scalar_unit(f16: bool, words: Option<u32>, lanes: u32) -> &'static str {
    match (f16, words) {
        (true, Some(1)) if lanes <= WIDEST_64_BIT_WORDS => {
            " alias Unit = u64; fn unit_f32(u: Unit) -> vec4<f32> \
             { return vec4<f32>(unpack2x16float(u32(u)), unpack2x16float(u32(u >> 32u))); } \
             fn f32_unit(v: vec4<f32>) -> Unit \
             { return u64(pack2x16float(v.xy)) | (u64(pack2x16float(v.zw)) << 32u); }"
        }
        (true, Some(_)) => {
            " alias Unit = vec2<u32>; fn unit_f32(u: Unit) -> vec4<f32> \
             { return vec4<f32>(unpack2x16float(u.x), unpack2x16float(u.y)); } \
             fn f32_unit(v: vec4<f32>) -> Unit { return vec2<u32>(pack2x16float(v.xy), pack2x16float(v.zw)); }"
        }
        (false, Some(1)) if lanes <= WIDEST_64_BIT_WORDS => {
            " alias Unit = vec2<u64>; fn unit_f32(u: Unit) -> vec4<f32> \
             { return bitcast<vec4<f32>>(vec4<u32>(u32(u.x), u32(u.x >> 32u), u32(u.y), u32(u.y >> 32u))); } \
             fn f32_unit(v: vec4<f32>) -> Unit { let w = bitcast<vec4<u32>>(v); \
             return vec2<u64>(u64(w.x) | (u64(w.y) << 32u), u64(w.z) | (u64(w.w) << 32u)); }"
        }
        _ => {
            " alias Unit = vec4<S>; fn unit_f32(u: Unit) -> vec4<f32> { return vec4<f32>(u); } \
             fn f32_unit(v: vec4<f32>) -> Unit { return Unit(v); }"
        }
    }
}

/// The products of a cooperative variant's matrices ([`Products`]): those declared 8×8 (the
/// prelude's FA, FB and FC) take the FM×FN×FK product; with PV = 1, those declared 16×16 take
/// the FM×FK×FN product that follows it (attention's P·V after Q·Kᵀ, FN keys and FK values a
/// head).
fn fragment_products(params: &[(&str, u32)]) -> Option<Vec<Product>> {
    let get = |name: &str| params.iter().find(|(n, _)| *n == name).map(|(_, v)| *v);
    let (m, n, k) = (get("FM")?, get("FN")?, get("FK")?);
    Some(match get("PV") {
        Some(1) => vec![(8, (m, n, k)), (16, (m, k, n))],
        _ => vec![(8, (m, n, k))],
    })
}

/// The scope of a cooperative variant's matrices: Workgroup (2) where WS = 1
/// (VK_NV_cooperative_matrix2's workgroup scope), else Subgroup (3), as naga writes them.
fn fragment_scope(params: &[(&str, u32)]) -> u32 {
    if params.contains(&("WS", 1)) {
        2
    } else {
        3
    }
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

/// Where a variant runs, which decides two of naga's guards. naga adds a 64-bit iteration counter
/// to every loop by default, a browser's guard against infinite loops (none here: each loop counts
/// to a bound); its second exit hides the loop's trip count from the driver's unroller. And its
/// `Restrict` policy clamps every index into a fixed-size array (workgroup memory among them) to
/// the array's end, which keeps each address from folding into the load's immediate offset.
///
/// - `Target::Gpu`: the GPU and matrix-unit kernels drop both, so that their compilers unroll as
///   they see fit (wgpu issue 7698: a compute pass 100× slower with the counter) and address
///   workgroup memory as written. Their indices are in range by construction (tiles of constant
///   shape, lanes and subgroups that the workgroup size bounds), and CI proves each kernel on
///   lavapipe's GPU paths. AMD's compiler (RADV's ACO, RDNA3, through `vkdiff devices --compile`)
///   estimated the tiled GEMM and convolution 26–29 % faster without the clamps, the matrix-unit
///   ones 3–7 %, and `attention_rows` stopped spilling at heads of 64.
/// - `Target::Any`: the kernels lavapipe's own paths run keep both: their JIT times were tuned with
///   them, and without the counter Mesa 26.1's 16-lane kernel tests took 430 s instead of 24 (376 s
///   with every loop marked DontUnroll instead, so it is not only the unroller that it holds back).
///   Buffers keep `Restrict` on every target.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Target {
    Any,
    Gpu,
}

/// SPIR-V words for `src`; on failure one message starting with `file:line: what: `, followed
/// by naga's rendering of the error.
fn compile(
    mut src: Source,
    params: &[(&str, u32)],
    (cooperative, target): (bool, Target),
    what: &str,
) -> Result<Vec<u32>, String> {
    use naga::{back::spv, valid};
    src.text = unroll(&src.text, params).map_err(|e| format!("{what}: {e}"))?;
    let module = naga::front::wgsl::parse_str(&src.text).map_err(|e| {
        let at = e.location(&src.text).map(|l| src.locate(l.line_number as usize));
        format!("{}: {what}: {}\n{}", at.unwrap_or_default(), e.message(), e.emit_to_string(&src.text))
    })?;
    let mut caps = valid::Capabilities::IMMEDIATES
        | valid::Capabilities::SHADER_FLOAT16
        | valid::Capabilities::SHADER_FLOAT16_IN_FLOAT32
        | valid::Capabilities::SUBGROUP
        | valid::Capabilities::SUBGROUP_BARRIER
        | valid::Capabilities::SHADER_INT64;
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
    // seconds of JIT on lavapipe), no StorageInputOutput16 (lavapipe lacks it), Restrict bounds for buffers; loop
    // counters and array indices as `target` says.
    // VK_NV_cooperative_matrix2's placeholders are found by their names: only their kernels carry naga's.
    let placeholders = cooperative && src.text.contains("fn nv_");
    let restrict = naga::proc::BoundsCheckPolicy::Restrict;
    let options = spv::Options {
        lang_version: (1, 3),
        flags: if placeholders { spv::WriterFlags::DEBUG } else { spv::WriterFlags::empty() },
        zero_initialize_workgroup_memory: spv::ZeroInitializeWorkgroupMemoryMode::Native,
        force_loop_bounding: target == Target::Any,
        use_storage_input_output_16: false,
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: if target == Target::Gpu { naga::proc::BoundsCheckPolicy::Unchecked } else { restrict },
            buffer: restrict,
            // The only images are the texel buffers (spirv_texels.rs), whose reads the kernels
            // clamp; naga's clamp would query mip levels, which a buffer has none of.
            image_load: naga::proc::BoundsCheckPolicy::Unchecked,
            binding_array: restrict,
        },
        ..Default::default()
    };
    let pipeline = spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: "main".into() };
    let words =
        spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| format!("{what}: SPIR-V output: {e}"))?;
    if params.contains(&("TB", 1)) {
        return texel_buffers(&words).map_err(|e| format!("{what}: texel buffers: {e}"));
    }
    if !cooperative {
        return Ok(words);
    }
    let products = fragment_products(params)
        .ok_or_else(|| format!("{what}: a cooperative kernel needs the parameters FM, FN and FK"))?;
    let scope = fragment_scope(params);
    let words = shape_fragments(&words, &products, scope).map_err(|e| format!("{what}: fragment shapes: {e}"))?;
    let words = workgroup_barriers(&words).map_err(|e| format!("{what}: barriers: {e}"))?;
    let (words, capabilities) = lower_placeholders(&words).map_err(|e| format!("{what}: {e}"))?;
    match scope == 2 || !capabilities.is_empty() {
        true => declare(&words, "SPV_NV_cooperative_matrix2", &capabilities).map_err(|e| format!("{what}: {e}")),
        false => Ok(words),
    }
}
