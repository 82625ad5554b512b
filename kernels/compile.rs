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
        (true, false) => "enable f16; alias S = f16; alias Unit = vec4<S>;",
        (false, false) => "alias S = f32; alias Unit = vec4<S>;",
    });
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

/// The fragment shape of a cooperative variant's parameters: (FM, FN, FK).
fn fragment_shape(params: &[(&str, u32)]) -> Option<(u32, u32, u32)> {
    let get = |name: &str| params.iter().find(|(n, _)| *n == name).map(|(_, v)| *v);
    Some((get("FM")?, get("FN")?, get("FK")?))
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

/// Gives every `OpTypeCooperativeMatrixKHR` in `words` the shape its use takes in an
/// M×N×K product: A (MatrixA) M×K, B (MatrixB) K×N, the accumulator M×N; A and B f16
/// components ([`prelude`]); and `scope` (a SPIR-V Scope). The scope, row and column counts are
/// 32-bit unsigned constants; those missing are declared just before the type.
fn shape_fragments(words: &[u32], (m, n, k): (u32, u32, u32), scope: u32) -> Result<Vec<u32>, String> {
    const OP_TYPE_INT: u32 = 21;
    const OP_TYPE_FLOAT: u32 = 22;
    const OP_CONSTANT: u32 = 43;
    const OP_TYPE_COOPERATIVE_MATRIX: u32 = 4456;
    let mut out = words.get(..5).ok_or("SPIR-V shorter than its header")?.to_vec();
    let mut bound = out[3];
    let mut uint = None;
    let mut f16 = None;
    let mut constants: Vec<(u32, u32)> = Vec::new(); // (value, id) of 32-bit unsigned constants
    let mut at = 5;
    while at < words.len() {
        let count = (words[at] >> 16) as usize;
        let op = words[at] & 0xffff;
        let inst = words.get(at..at + count).filter(|_| count > 0).ok_or("truncated SPIR-V instruction")?;
        match op {
            OP_TYPE_INT if inst[2..] == [32, 0] => uint = Some(inst[1]),
            OP_TYPE_FLOAT if inst[2] == 16 => f16 = Some(inst[1]),
            OP_CONSTANT if Some(inst[1]) == uint && count == 4 => constants.push((inst[3], inst[2])),
            OP_TYPE_COOPERATIVE_MATRIX if count == 7 => {
                let value = |id: u32| constants.iter().find(|(_, c)| *c == id).map(|(v, _)| *v);
                let f16 = f16.ok_or("no f16 type before a cooperative matrix");
                let (rows, cols, component) = match value(inst[6]) {
                    Some(0) => (m, k, f16?),
                    Some(1) => (k, n, f16?),
                    Some(2) => (m, n, inst[2]),
                    other => return Err(format!("cooperative matrix use {other:?}: not A, B or an accumulator")),
                };
                let uint = uint.ok_or("no 32-bit unsigned type before a cooperative matrix")?;
                let mut id_of = |v: u32| {
                    if let Some(&(_, id)) = constants.iter().find(|(x, _)| *x == v) {
                        return id;
                    }
                    let id = bound;
                    bound += 1;
                    out.extend([(4 << 16) | OP_CONSTANT, uint, id, v]);
                    constants.push((v, id));
                    id
                };
                let (s, r, c) = (id_of(scope), id_of(rows), id_of(cols));
                out.extend([inst[0], inst[1], component, s, r, c, inst[6]]);
                at += count;
                continue;
            }
            _ => {}
        }
        out.extend_from_slice(inst);
        at += count;
    }
    out[3] = bound;
    Ok(out)
}

/// `words` with `OpExtension "name"` declared after the capabilities, before the first
/// instruction that must follow the extensions (an import or the memory model).
fn with_extension(words: &[u32], name: &str) -> Result<Vec<u32>, String> {
    const OP_EXTENSION: u32 = 10;
    const FOLLOWERS: [u32; 2] = [11, 14]; // OpExtInstImport, OpMemoryModel
    let mut at = 5;
    while at < words.len() && !FOLLOWERS.contains(&(words[at] & 0xffff)) {
        at += (words[at] >> 16).max(1) as usize;
    }
    if at >= words.len() {
        return Err("no memory model to declare an extension before".into());
    }
    // A literal string: its UTF-8 bytes and a NUL, in little-endian words.
    let mut bytes = name.as_bytes().to_vec();
    bytes.resize((bytes.len() / 4 + 1) * 4, 0);
    let literal = bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
    let mut out = words[..at].to_vec();
    out.push(((1 + bytes.len() as u32 / 4) << 16) | OP_EXTENSION);
    out.extend(literal);
    out.extend_from_slice(&words[at..]);
    Ok(out)
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
        | valid::Capabilities::SUBGROUP;
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
    let restrict = naga::proc::BoundsCheckPolicy::Restrict;
    let options = spv::Options {
        lang_version: (1, 3),
        flags: spv::WriterFlags::empty(),
        zero_initialize_workgroup_memory: spv::ZeroInitializeWorkgroupMemoryMode::Native,
        force_loop_bounding: target == Target::Any,
        use_storage_input_output_16: false,
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: if target == Target::Gpu { naga::proc::BoundsCheckPolicy::Unchecked } else { restrict },
            buffer: restrict,
            image_load: restrict,
            binding_array: restrict,
        },
        ..Default::default()
    };
    let pipeline = spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: "main".into() };
    let words =
        spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| format!("{what}: SPIR-V output: {e}"))?;
    match fragment_shape(params).filter(|_| cooperative) {
        Some(shape) => {
            let scope = fragment_scope(params);
            let words = shape_fragments(&words, shape, scope).map_err(|e| format!("{what}: fragment shapes: {e}"))?;
            match scope {
                2 => with_extension(&words, "SPV_NV_cooperative_matrix2").map_err(|e| format!("{what}: {e}")),
                _ => Ok(words),
            }
        }
        None if cooperative => Err(format!("{what}: a cooperative kernel needs the parameters FM, FN and FK")),
        None => Ok(words),
    }
}
