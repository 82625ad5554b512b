// Attention's operands (attention_common.wgsl), in the units the kernels read them.
@group(0) @binding(0) var<storage, read> q: array<Unit>;
@group(0) @binding(1) var<storage, read> k: array<Unit>;
@group(0) @binding(2) var<storage, read> v: array<Unit>;
@group(0) @binding(3) var<storage, read_write> o: array<Unit>;
