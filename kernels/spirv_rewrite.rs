// The build's rewrites of naga's SPIR-V for the matrix-unit kernels, where WGSL cannot say what
// the kernel means: the matrices' shapes and scope, and VK_NV_cooperative_matrix2's reductions,
// per-element operations and conversions, written in WGSL as calls of placeholder functions.
// Included by compile.rs.

/// The product matrices belong to, by the side naga declares them with (8 or 16): an M×N×K
/// product gives its A (MatrixA) M×K, its B (MatrixB) K×N and its accumulator M×N.
type Product = (u32, (u32, u32, u32));
type Products = [Product];

/// Gives every `OpTypeCooperativeMatrixKHR` in `words` the shape its use takes in the product
/// of its declared side ([`Products`]); A and B f16 components ([`prelude`]); and `scope` (a
/// SPIR-V Scope). The scope, row and column counts are 32-bit unsigned constants; those missing
/// are declared just before the type. Two matrix types that would coincide are an error (SPIR-V
/// allows one declaration of each).
fn shape_fragments(words: &[u32], products: &Products, scope: u32) -> Result<Vec<u32>, String> {
    const OP_TYPE_INT: u32 = 21;
    const OP_TYPE_FLOAT: u32 = 22;
    const OP_CONSTANT: u32 = 43;
    const OP_TYPE_COOPERATIVE_MATRIX: u32 = 4456;
    let mut out = words.get(..5).ok_or("SPIR-V shorter than its header")?.to_vec();
    let mut bound = out[3];
    let mut uint = None;
    let mut f16 = None;
    let mut constants: Vec<(u32, u32)> = Vec::new(); // (value, id) of 32-bit unsigned constants
    let mut declared: Vec<[u32; 5]> = Vec::new(); // (component, scope, rows, columns, use) of each matrix type
    for inst in instructions(words)? {
        match inst[0] & 0xffff {
            OP_TYPE_INT if inst[2..] == [32, 0] => uint = Some(inst[1]),
            OP_TYPE_FLOAT if inst[2] == 16 => f16 = Some(inst[1]),
            OP_CONSTANT if Some(inst[1]) == uint && inst.len() == 4 => constants.push((inst[3], inst[2])),
            OP_TYPE_COOPERATIVE_MATRIX if inst.len() == 7 => {
                let value = |id: u32| constants.iter().find(|(_, c)| *c == id).map(|(v, _)| *v);
                let side = value(inst[4]);
                let &(_, (m, n, k)) = products
                    .iter()
                    .find(|(s, _)| Some(*s) == side)
                    .ok_or_else(|| format!("no product for matrices declared {side:?} a side"))?;
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
                let key = [component, s, r, c, inst[6]];
                if declared.contains(&key) {
                    return Err(format!("two matrix types of one use coincide at {rows}×{cols}"));
                }
                declared.push(key);
                out.extend([inst[0], inst[1], component, s, r, c, inst[6]]);
                continue;
            }
            _ => {}
        }
        out.extend_from_slice(inst);
    }
    out[3] = bound;
    Ok(out)
}

/// `words` with each `OpControlBarrier` given the scopes and semantics the matrix-unit kernels
/// mean by it under the Vulkan memory model (which naga's cooperative SPIR-V declares):
/// - Device memory scope becomes Workgroup. naga writes WGSL's `storageBarrier()` with Device
///   scope, which needs the VulkanMemoryModelDeviceScope capability; these kernels order storage
///   accesses among a workgroup's invocations only, which Workgroup scope says.
/// - A barrier of Subgroup execution scope (WGSL's `subgroupBarrier()`) orders workgroup memory,
///   as GLSL's `subgroupMemoryBarrierShared(); subgroupBarrier();` does. naga gives it the
///   SubgroupMemory semantics only, which Vulkan ignores, so the lanes of a subgroup would not see
///   each other's writes to the subgroup's own rows of a tile (a matrix store then per-lane loads).
fn workgroup_barriers(words: &[u32]) -> Result<Vec<u32>, String> {
    const OP_TYPE_INT: u32 = 21;
    const OP_CONSTANT: u32 = 43;
    const OP_CONTROL_BARRIER: u32 = 224;
    const DEVICE: u32 = 1; // Scope
    const WORKGROUP: u32 = 2;
    const SUBGROUP: u32 = 3;
    const ORDERS_WORKGROUP_MEMORY: u32 = 0x8 | 0x100; // AcquireRelease | WorkgroupMemory
    let insts = instructions(words)?;
    let uint = insts.iter().find(|i| i[0] & 0xffff == OP_TYPE_INT && i[2..] == [32, 0]).map(|i| i[1]);
    let constant = |value: u32| {
        let is = |i: &&&[u32]| i[0] & 0xffff == OP_CONSTANT && Some(i[1]) == uint && i.len() == 4 && i[3] == value;
        insts.iter().find(is).map(|i| i[2])
    };
    let (device, workgroup, subgroup) = (constant(DEVICE), constant(WORKGROUP), constant(SUBGROUP));
    let mut out = words[..5].to_vec();
    for inst in insts.iter() {
        if inst[0] & 0xffff == OP_CONTROL_BARRIER && Some(inst[2]) == device {
            let workgroup = workgroup.ok_or("a device-scope barrier and no Workgroup scope constant")?;
            out.extend([inst[0], inst[1], workgroup, inst[3]]);
            continue;
        }
        if inst[0] & 0xffff == OP_CONTROL_BARRIER && Some(inst[1]) == subgroup {
            // naga declares this constant for every workgroupBarrier(); a kernel with a subgroup
            // barrier and none has no workgroup memory to order.
            let orders = constant(ORDERS_WORKGROUP_MEMORY).ok_or("a subgroup barrier and no workgroup barrier's semantics")?;
            out.extend([inst[0], inst[1], inst[2], orders]);
            continue;
        }
        out.extend_from_slice(inst);
    }
    Ok(out)
}

/// A SPIR-V literal string: its UTF-8 bytes and a NUL, in little-endian words.
fn literal(name: &str) -> Vec<u32> {
    let mut bytes = name.as_bytes().to_vec();
    bytes.resize((bytes.len() / 4 + 1) * 4, 0);
    bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

/// The literal string that `words` (an instruction's operands from the string on) begin with.
fn string_of(words: &[u32]) -> String {
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).take_while(|&b| b != 0).collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

/// `words` with `OpExtension "name"` and `OpCapability` for each of `capabilities`: the
/// capabilities after naga's, the extension before the first instruction that must follow the
/// extensions (an import or the memory model).
fn declare(words: &[u32], name: &str, capabilities: &[u32]) -> Result<Vec<u32>, String> {
    const OP_CAPABILITY: u32 = 17;
    const OP_EXTENSION: u32 = 10;
    const FOLLOWERS: [u32; 2] = [11, 14]; // OpExtInstImport, OpMemoryModel
    let insts = instructions(words)?;
    let start = |i: usize| 5 + insts[..i].iter().map(|inst| inst.len()).sum::<usize>();
    let caps_end = start(insts.iter().take_while(|i| i[0] & 0xffff == OP_CAPABILITY).count());
    let followers = insts.iter().position(|i| FOLLOWERS.contains(&(i[0] & 0xffff)));
    let at = start(followers.ok_or("no memory model to declare an extension before")?);
    let mut out = words[..caps_end].to_vec();
    for &capability in capabilities {
        out.extend([(2 << 16) | OP_CAPABILITY, capability]);
    }
    out.extend_from_slice(&words[caps_end..at]);
    let name = literal(name);
    out.push(((1 + name.len() as u32) << 16) | OP_EXTENSION);
    out.extend(name);
    out.extend_from_slice(&words[at..]);
    Ok(out)
}

/// VK_NV_cooperative_matrix2's operations, written in WGSL as calls of placeholder functions
/// (naga 30 spells none of them), by the placeholder's name:
///
/// - `nv_reduce_rows…(m, f(…))`: each row of the accumulator `m` reduced by the function `f`
///   (two elements to one), into every element of the result's row;
/// - `nv_each…(m, f(…), operands…)`: `f(row, column, element, operands…)` for each element of
///   `m`, matrix operands passing their corresponding element;
/// - `nv_convert…(m)`: an accumulator converted to the result's component type and use.
///
/// A placeholder's body only gives naga a result of the right type; `f(…)`, its call with any
/// arguments, only names the function, and is removed.
#[derive(Clone, Copy, PartialEq)]
enum Placeholder {
    ReduceRows,
    Each,
    Convert,
}

impl Placeholder {
    /// The opcode and capability each placeholder becomes.
    fn of(name: &str) -> Option<Result<(Placeholder, u32, u32), String>> {
        let name = name.strip_prefix("nv_")?;
        Some(match name {
            _ if name.starts_with("reduce_rows") => Ok((Placeholder::ReduceRows, 5366, 5430)),
            _ if name.starts_with("each") => Ok((Placeholder::Each, 5369, 5432)),
            _ if name.starts_with("convert") => Ok((Placeholder::Convert, 115, 5431)),
            _ => Err(format!("`nv_{name}`: not a placeholder of VK_NV_cooperative_matrix2 (nv_reduce_rows…, nv_each…, nv_convert…)")),
        })
    }
}

/// `words` with every call of a placeholder ([`Placeholder`]; names come from naga's debug
/// names) replaced by the instruction it stands for, and the capabilities those need, in the
/// order first used.
fn lower_placeholders(words: &[u32]) -> Result<(Vec<u32>, Vec<u32>), String> {
    const OP_NAME: u32 = 5;
    const OP_FUNCTION: u32 = 54;
    const OP_FUNCTION_END: u32 = 56;
    const OP_FUNCTION_CALL: u32 = 57;
    const ROW: u32 = 1; // CooperativeMatrixReduce Row
    let insts = instructions(words)?;
    let mut names = std::collections::HashMap::new();
    let mut callee = std::collections::HashMap::new(); // call result → function called
    for inst in &insts {
        match inst[0] & 0xffff {
            OP_NAME => _ = names.insert(inst[1], string_of(&inst[2..])),
            OP_FUNCTION_CALL => _ = callee.insert(inst[2], inst[3]),
            _ => {}
        }
    }
    let placeholder = |function: u32| names.get(&function).and_then(|n| Placeholder::of(n)).transpose();
    // The calls that only name a function to a placeholder.
    let mut naming = std::collections::HashSet::new();
    for inst in insts.iter().filter(|i| i[0] & 0xffff == OP_FUNCTION_CALL) {
        if let Some((kind, ..)) = placeholder(inst[3])? {
            if inst.len() < 5 {
                return Err(format!("`{}`: takes the matrix as its first argument", names[&inst[3]]));
            }
            if kind != Placeholder::Convert {
                let named = inst.get(5).filter(|id| callee.contains_key(id));
                naming.insert(*named.ok_or_else(|| format!("`{}`: its second argument must call a function", names[&inst[3]]))?);
            }
        }
    }
    // The functions the operations apply go after every other (after the entry point, as glslang
    // places them): Mesa 26.1's lavapipe crashes compiling a kernel where they come first.
    let applied: std::collections::HashSet<u32> = naming.iter().map(|id| callee[id]).collect();
    let (mut out, mut last) = (words[..5].to_vec(), Vec::new());
    let mut in_applied = false;
    let mut capabilities = Vec::new();
    for inst in insts {
        let op = inst[0] & 0xffff;
        if (op == OP_FUNCTION_CALL && naming.contains(&inst[2])) || (op == OP_NAME && naming.contains(&inst[1])) {
            continue;
        }
        in_applied |= op == OP_FUNCTION && applied.contains(&inst[2]);
        let sink = if in_applied { &mut last } else { &mut out };
        in_applied &= op != OP_FUNCTION_END;
        let lowering = match op {
            OP_FUNCTION_CALL => placeholder(inst[3])?,
            _ => None,
        };
        let Some((kind, opcode, capability)) = lowering else {
            sink.extend_from_slice(inst);
            continue;
        };
        if !capabilities.contains(&capability) {
            capabilities.push(capability);
        }
        let (result_type, result, args) = (inst[1], inst[2], &inst[4..]);
        let lowered: Vec<u32> = match kind {
            Placeholder::ReduceRows => vec![result_type, result, args[0], ROW, callee[&args[1]]],
            Placeholder::Each => [result_type, result, args[0], callee[&args[1]]].into_iter().chain(args[2..].iter().copied()).collect(),
            Placeholder::Convert => vec![result_type, result, args[0]],
        };
        sink.push(((1 + lowered.len() as u32) << 16) | opcode);
        sink.extend(lowered);
    }
    out.extend(last);
    Ok((out, capabilities))
}
