//! vkdiff's compute kernels: WGSL sources in `wgsl/`, compiled and validated by naga in `build.rs`,
//! embedded here as SPIR-V, one blob per variant (storage dtype × compile-time parameters).

include!("spec.rs");
include!("spec_cooperative.rs");
include!("spirv_words.rs");
include!("broadcasts.rs");

/// One compiled variant of a kernel.
pub struct Variant {
    pub kernel: &'static str,
    pub dtype: Dtype,
    /// Compile-time parameters (tile sizes, subgroup width, operation codes).
    pub params: &'static [(&'static str, u32)],
    /// Little-endian SPIR-V words.
    pub spirv: &'static [u8],
}

include!(concat!(env!("OUT_DIR"), "/variants.rs"));

impl Variant {
    /// The value of a compile-time parameter, if this kernel has it.
    pub fn param(&self, name: &str) -> Option<u32> {
        self.params.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
    }

    /// SPIR-V as words (the embedded bytes carry no alignment guarantee).
    pub fn words(&self) -> Vec<u32> {
        self.spirv.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
    }
}

/// Every compiled variant of `kernel` in `dtype`.
pub fn variants(kernel: &str, dtype: Dtype) -> impl Iterator<Item = &'static Variant> + '_ {
    VARIANTS.iter().filter(move |v| v.kernel == kernel && v.dtype == dtype)
}

/// The variant of `kernel` whose parameters include every `(name, value)` in `want`.
pub fn find(kernel: &str, dtype: Dtype, want: &[(&str, u32)]) -> Option<&'static Variant> {
    variants(kernel, dtype).find(|v| want.iter().all(|(n, x)| v.param(n) == Some(*x)))
}

/// The build-time compiler, tested on sources written to fail.
#[cfg(test)]
mod compile_tests {
    use super::{instructions, WIDEST_64_BIT_WORDS};
    include!("../compile.rs");

    fn one_file(body: &str) -> Source {
        Source::new(
            &prelude(false, &[("N", 2)], false),
            &[("a.wgsl".into(), "// line 1\n".into()), ("broken.wgsl".into(), body.into())],
        )
    }

    #[test]
    fn parse_errors_name_the_file_and_line() {
        let err = compile(
            one_file("@compute @workgroup_size(1)\nfn main() {\n    let x = ;\n}\n"),
            &[],
            (false, Target::Gpu),
            "kernel `t`",
        )
        .unwrap_err();
        assert!(err.starts_with("kernels/wgsl/broken.wgsl:3: kernel `t`"), "{err}");
    }

    #[test]
    fn validation_errors_name_the_file_and_line() {
        let body = "@compute @workgroup_size(1)\nfn main() {\n    var x: u32 = 1u;\n    x = 1.5 + x;\n}\n";
        let err = compile(one_file(body), &[], (false, Target::Gpu), "kernel `t`").unwrap_err();
        assert!(err.starts_with("kernels/wgsl/broken.wgsl:4:"), "{err}");
    }

    #[test]
    fn unrolled_blocks_keep_line_numbers() {
        let body = "var<workgroup> w: array<u32, 4>;\n@compute @workgroup_size(1)\nfn main() \
            {\n    // #unroll I N\n    w[I] = I; // a comment\n    // #end\n    let y = ;\n}\n";
        let err = compile(one_file(body), &[("N", 2)], (false, Target::Gpu), "kernel `t`").unwrap_err();
        assert!(err.starts_with("kernels/wgsl/broken.wgsl:7:"), "{err}");
    }

    #[test]
    fn unroll_substitutes_whole_words_only() {
        let text = "a\n// #unroll R 2\nx[R] = RR + R;\n// #end\nb";
        assert_eq!(unroll(text, &[]).unwrap(), "a\nx[0u] = RR + 0u; x[1u] = RR + 1u;\n\n\nb");
        assert!(unroll("// #unroll R Q\n// #end", &[]).unwrap_err().contains("count is not numbers and parameters"));
    }

    #[test]
    fn unroll_counts_are_products_and_quotients_of_parameters() {
        let params = [("CM", 16), ("SG", 32)];
        assert_eq!(unroll_count("2*CM*CM/SG", &params), Some(16));
        assert_eq!(unroll_count("SG", &params), Some(32));
        assert_eq!(unroll_count("CM/3", &params), None, "a remainder");
        assert_eq!(unroll_count("CM*", &params), None);
        assert_eq!(unroll_count("CM+1", &params), None);
        assert_eq!(unroll_count("CM/0", &params), None);
    }

    /// (rows, columns, use, component bits) of each cooperative matrix type in `words`.
    fn fragment_types(words: &[u32]) -> Vec<(u32, u32, u32, u32)> {
        let (mut constants, mut floats, mut types) = (Vec::new(), Vec::new(), Vec::new());
        for inst in instructions(words).unwrap() {
            let value = |id: u32| constants.iter().find(|(c, _)| *c == id).map(|(_, v)| *v).unwrap();
            let bits = |id: u32| floats.iter().find(|(f, _)| *f == id).map(|(_, b)| *b).unwrap();
            match inst[0] & 0xffff {
                22 => floats.push((inst[1], inst[2])),
                43 => constants.push((inst[2], inst[3])),
                4456 => types.push((value(inst[4]), value(inst[5]), value(inst[6]), bits(inst[2]))),
                _ => {}
            }
        }
        types
    }

    #[test]
    fn fragments_take_the_variants_shape_by_use_and_f16_operands() {
        let body = "var<workgroup> w: array<vec2<f32>, 64>;\n@compute @workgroup_size(SG)\nfn main() {\n    \
            let a = coopLoadT<FA>(&w[0], 4u);\n    let b = coopLoad<FB>(&w[0], 4u);\n    var c: FC;\n    \
            c = coopMultiplyAdd(a, b, c);\n}\n";
        let params = [("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16)];
        let src = Source::new(&prelude(true, &params, true), &[("k.wgsl".into(), body.into())]);
        let words = compile(src, &params, (true, Target::Gpu), "kernel `t`").unwrap();
        let mut types = fragment_types(&words);
        types.sort_by_key(|t| t.2);
        assert_eq!(types, [(8, 16, 0, 16), (16, 16, 1, 16), (8, 16, 2, 32)], "A 8×16, B 16×16 f16, C 8×16 f32");
        let square = [("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8)];
        let src = Source::new(&prelude(true, &square, true), &[("k.wgsl".into(), body.into())]);
        let words = compile(src, &square, (true, Target::Gpu), "kernel `t`").unwrap();
        assert!(fragment_types(&words).iter().all(|&(r, c, _, _)| (r, c) == (8, 8)));
        let src = Source::new(&prelude(true, &[("SG", 8)], true), &[("k.wgsl".into(), body.into())]);
        let err = compile(src, &[("SG", 8)], (true, Target::Gpu), "kernel `t`").unwrap_err();
        assert!(err.contains("needs the parameters FM, FN and FK"), "{err}");
    }

    /// The scopes of the cooperative matrix types in `words`, and its extensions' names.
    fn scopes_and_extensions(words: &[u32]) -> (Vec<u32>, Vec<String>) {
        let (mut constants, mut scopes, mut extensions) = (Vec::new(), Vec::new(), Vec::new());
        for inst in instructions(words).unwrap() {
            match inst[0] & 0xffff {
                10 => extensions.push(string_of(&inst[1..])),
                43 => constants.push((inst[2], inst[3])),
                4456 => scopes.push(constants.iter().find(|(c, _)| *c == inst[3]).map(|(_, v)| *v).unwrap()),
                _ => {}
            }
        }
        (scopes, extensions)
    }

    #[test]
    fn workgroup_scope_variants_declare_cooperative_matrix2() {
        let body = "@group(0) @binding(0) var<storage, read_write> w: array<f32>;\n@compute @workgroup_size(SG)\n\
            fn main() {\n    let a = coopLoadT<FA>(&w[0], 4u);\n    let b = coopLoad<FB>(&w[0], 4u);\n    var c: FC;\n    \
            c = coopMultiplyAdd(a, b, c);\n    coopStoreT(c, &w[0], 4u);\n}\n";
        let cm2 = "SPV_NV_cooperative_matrix2".to_string();
        for (ws, scope) in [(0, 3), (1, 2)] {
            let params = [("FM", 32), ("FN", 32), ("FK", 16), ("SG", 8), ("WS", ws)];
            let src = Source::new(&prelude(true, &params, true), &[("k.wgsl".into(), body.into())]);
            let words = compile(src, &params, (true, Target::Gpu), "kernel `t`").unwrap();
            let (scopes, extensions) = scopes_and_extensions(&words);
            assert_eq!(scopes, [scope; 3], "WS = {ws}: every matrix of scope {scope}");
            assert_eq!(extensions.contains(&cm2), ws == 1, "WS = {ws}: {extensions:?}");
            assert!(extensions.contains(&"SPV_KHR_cooperative_matrix".to_string()), "{extensions:?}");
        }
    }

    /// A kernel on VK_NV_cooperative_matrix2's placeholders (spirv_rewrite.rs): a row maximum,
    /// a per-element sum with a matrix operand, and a conversion to an A operand.
    const PLACEHOLDERS: &str = "@group(0) @binding(0) var<storage, read_write> w: array<f32>;\n\
        fn larger(a: f32, b: f32) -> f32 {\n    return max(a, b);\n}\n\
        fn plus(row: u32, col: u32, x: f32, y: f32) -> f32 {\n    return x + y;\n}\n\
        fn nv_reduce_rows(m: FC, f: f32) -> FC {\n    return m;\n}\n\
        fn nv_each_with(m: FC, f: f32, y: FC) -> FC {\n    return m;\n}\n\
        fn nv_convert(m: FC) -> FA {\n    var z: FA;\n    return z;\n}\n\
        @compute @workgroup_size(SG)\nfn main() {\n    let c = coopLoadT<FC>(&w[0], 8u);\n    \
        let r = nv_each_with(nv_reduce_rows(c, larger(0.0, 0.0)), plus(0u, 0u, 0.0, 0.0), c);\n    \
        var acc: FC;\n    acc = coopMultiplyAdd(nv_convert(r), coopLoad<FB>(&w[0], 8u), acc);\n    \
        coopStoreT(acc, &w[0], 8u);\n}\n";

    fn compile_placeholders(body: &str, params: &[(&str, u32)]) -> Result<Vec<u32>, String> {
        let src = Source::new(&prelude(true, params, true), &[("k.wgsl".into(), body.into())]);
        compile(src, params, (true, Target::Gpu), "kernel `t`")
    }

    #[test]
    fn placeholders_become_the_extension_s_operations() {
        let params = [("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8)];
        let words = compile_placeholders(PLACEHOLDERS, &params).unwrap();
        let insts = instructions(&words).unwrap();
        let id_named =
            |name: &str| insts.iter().find(|i| i[0] & 0xffff == 5 && string_of(&i[2..]) == name).map(|i| i[1]).unwrap();
        let (larger, plus, main) = (id_named("larger"), id_named("plus"), id_named("main"));
        let of = |op: u32| insts.iter().filter(move |i| i[0] & 0xffff == op);
        let reduce: Vec<_> = of(5366).collect();
        assert!(reduce.len() == 1 && reduce[0][4] == 1 && reduce[0][5] == larger, "a row reduction by `larger`");
        let each: Vec<_> = of(5369).collect();
        assert!(each.len() == 1 && each[0][4] == plus && each[0].len() == 6, "`plus` with one matrix operand");
        assert_eq!(of(115).count(), 1, "one OpFConvert");
        assert_eq!(of(57).count(), 0, "no call is left: the placeholders' and the naming ones are gone");
        let capabilities: Vec<u32> = of(17).map(|i| i[1]).collect();
        assert!([5430, 5431, 5432].iter().all(|c| capabilities.contains(c)), "{capabilities:?}");
        let (_, extensions) = scopes_and_extensions(&words);
        assert!(extensions.contains(&"SPV_NV_cooperative_matrix2".to_string()), "{extensions:?}");
        let at = |f: u32| insts.iter().position(|i| i[0] & 0xffff == 54 && i[2] == f).unwrap();
        assert!(at(main) < at(larger) && at(main) < at(plus), "the applied functions follow the entry point");
    }

    #[test]
    fn placeholders_misused_and_coinciding_shapes_are_build_errors() {
        let params = [("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8)];
        let unknown = PLACEHOLDERS.replace("nv_convert", "nv_transpose");
        let err = compile_placeholders(&unknown, &params).unwrap_err();
        assert!(err.contains("`nv_transpose`: not a placeholder"), "{err}");
        let uncalled = PLACEHOLDERS.replace("nv_reduce_rows(c, larger(0.0, 0.0))", "nv_reduce_rows(c, 1.0)");
        let err = compile_placeholders(&uncalled, &params).unwrap_err();
        assert!(err.contains("`nv_reduce_rows`: its second argument must call a function"), "{err}");
        // PV = 1 gives 16×16 declarations the second product; with FN = FK its matrices would
        // repeat the first's types.
        let second = "@group(0) @binding(0) var<storage, read_write> w: array<f32>;\n@compute @workgroup_size(SG)\n\
            fn main() {\n    let a = coopLoadT<FC>(&w[0], 8u);\n    let b = coopLoadT<coop_mat16x16<f32, C>>(&w[0], 8u);\n    \
            coopStoreT(a, &w[0], 8u);\n    coopStoreT(b, &w[0], 8u);\n}\n";
        let err = compile_placeholders(second, &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("PV", 1)]).unwrap_err();
        assert!(err.contains("two matrix types of one use coincide at 8×16"), "{err}");
        let words = compile_placeholders(second, &[("FM", 8), ("FN", 16), ("FK", 32), ("SG", 8), ("PV", 1)]).unwrap();
        let mut types = fragment_types(&words);
        types.sort();
        // The prelude's A and B (8×32 and 32×16 f16) and S (8×16) take Q·Kᵀ's shapes, the 16×16
        // accumulator P·V's (8×32).
        assert_eq!(types, [(8, 16, 2, 32), (8, 32, 0, 16), (8, 32, 2, 32), (32, 16, 1, 16)]);
    }

    #[test]
    fn cooperative_kernels_barriers_take_the_scopes_and_semantics_they_mean() {
        let body = "@group(0) @binding(0) var<storage, read_write> w: array<f32>;\n\
            var<workgroup> t: array<f32, 64>;\n@compute @workgroup_size(SG)\nfn main() {\n    \
            let a = coopLoadT<FC>(&w[0], 8u);\n    storageBarrier();\n    coopStoreT(a, &t[0], 8u);\n    \
            subgroupBarrier();\n    w[1] = t[2];\n    workgroupBarrier();\n    w[2] = t[3];\n}\n";
        let words = compile_placeholders(body, &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8)]).unwrap();
        let insts = instructions(&words).unwrap();
        let value = |id: u32| insts.iter().find(|i| i[0] & 0xffff == 43 && i[2] == id).map(|i| i[3]);
        let barriers: Vec<_> =
            insts.iter().filter(|i| i[0] & 0xffff == 224).map(|i| (value(i[1]), value(i[2]), value(i[3]))).collect();
        let (workgroup, subgroup, orders_workgroup_memory) = (Some(2), Some(3), Some(0x108));
        assert_eq!(
            barriers,
            [
                (workgroup, workgroup, Some(0x48)), // storage: AcquireRelease | UniformMemory
                (subgroup, subgroup, orders_workgroup_memory),
                (workgroup, workgroup, orders_workgroup_memory),
            ],
            "storageBarrier at Workgroup memory scope, subgroupBarrier ordering workgroup memory"
        );
    }

    /// Whether `words` hold a composite of 32-bit all-ones constants: naga's loop-bounding
    /// counter starts at vec2(u32::MAX), and nothing in a kernel builds one.
    fn has_loop_counter(words: &[u32]) -> bool {
        let mut all_ones = Vec::new();
        instructions(words).unwrap().into_iter().any(|inst| match inst[0] & 0xffff {
            43 if inst.len() == 4 && inst[3] == u32::MAX => {
                all_ones.push(inst[2]);
                false
            }
            44 => inst[3..].iter().all(|c| all_ones.contains(c)),
            _ => false,
        })
    }

    /// Whether `words` clamp an index with GLSL.std.450's UMin (naga's `Restrict` policy).
    fn clamps_an_index(words: &[u32]) -> bool {
        instructions(words).unwrap().iter().any(|i| i[0] & 0xffff == 12 && i[4] == 38)
    }

    #[test]
    fn only_kernels_for_any_device_keep_naga_s_loop_counter_and_index_clamps() {
        let body = "var<workgroup> w: array<u32, 8>;\n@compute @workgroup_size(1)\nfn main() {\n    \
            for (var i = 0u; i < 8u; i++) {\n        w[i] = i;\n    }\n}\n";
        for target in [Target::Gpu, Target::Any] {
            let words = compile(one_file(body), &[], (false, target), "kernel `t`").unwrap();
            assert!(
                instructions(&words).unwrap().iter().any(|i| i[0] & 0xffff == 246),
                "the loop is there (OpLoopMerge)"
            );
            assert_eq!(has_loop_counter(&words), target == Target::Any, "{target:?}");
            assert_eq!(clamps_an_index(&words), target == Target::Any, "{target:?}");
        }
    }

    #[test]
    fn gpu_kernels_carry_no_loop_counter_and_lavapipe_s_keep_it() {
        let gpu = |name: &str| {
            crate::GPU_KERNELS.contains(&name) || crate::COOPERATIVE_KERNELS.iter().any(|k| k.name == name)
        };
        let wrong: Vec<String> = crate::VARIANTS
            .iter()
            .filter(|v| has_loop_counter(&v.words()) == gpu(v.kernel) && (gpu(v.kernel) || v.kernel == "gemm_sg"))
            .map(|v| format!("{} {:?} {:?}", v.kernel, v.dtype, v.params))
            .collect();
        assert!(wrong.is_empty(), "GPU kernels with naga's loop counter, or subgroup GEMMs without: {wrong:?}");
        assert!(crate::GPU_KERNELS.iter().all(|name| crate::KERNELS.iter().any(|k| k.name == *name)));
    }

    #[test]
    fn a_valid_kernel_compiles_to_spirv() {
        let words =
            compile(one_file("@compute @workgroup_size(N)\nfn main() {}\n"), &[], (false, Target::Gpu), "kernel `t`")
                .unwrap();
        assert_eq!(words[0], 0x0723_0203, "SPIR-V magic number");
    }

    /// naga 30 compiles `&&` and `||` with short-circuit control flow: a branch (and, on NVIDIA,
    /// its branch-sync instructions) around every load that such a condition masked, which NAK
    /// showed around each of the matrix-unit GEMM's loads. The kernels combine comparisons with
    /// `&` and `|`, whose operands here are always safe to evaluate.
    #[test]
    fn kernels_combine_comparisons_without_short_circuits() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("wgsl");
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let text = std::fs::read_to_string(&path).unwrap();
            for (n, line) in text.lines().enumerate() {
                let code = line.split("//").next().unwrap();
                assert!(!code.contains("&&") && !code.contains("||"), "{}:{}: {line}", path.display(), n + 1);
            }
        }
    }
}
