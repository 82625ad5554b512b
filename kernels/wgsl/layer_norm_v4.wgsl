// LayerNorm over rows of C = 4·c4 values, one workgroup of 64 per row, in vec4s: one pass sums
// the row's values and squares shifted by its first value (so a large mean costs no precision:
// the variance is E[d²] − E[d]² of d = x − x₀, which stays small where the spread is small),
// with both sums reduced together behind one barrier, then one pass applies the affine map.
// The row is read twice, four values a load (layer_norm.wgsl: three times, one value a load).
@group(0) @binding(0) var<storage, read> x: array<vec4<S>>;
@group(0) @binding(1) var<storage, read> gamma: array<vec4<S>>;
@group(0) @binding(2) var<storage, read> beta: array<vec4<S>>;
@group(0) @binding(3) var<storage, read_write> y: array<vec4<S>>;

struct Params {
    c4: u32,
    eps: f32,
    groups_x: u32,
}

var<immediate> p: Params;

const WG: u32 = 64u;

var<workgroup> partial: array<vec2<f32>, WG>; // one sum pair per subgroup

// Both sums over the workgroup: within each subgroup by its arithmetic, then across subgroups
// in a fixed order, behind one barrier.
fn workgroup_sum2(v: vec2<f32>, sid: u32, lane: u32, subgroups: u32) -> vec2<f32> {
    let own = subgroupAdd(v);
    if lane == 0u {
        partial[sid] = own;
    }
    workgroupBarrier();
    var total = vec2<f32>(0.0);
    for (var i = 0u; i < subgroups; i++) {
        total += partial[i];
    }
    return total;
}

@compute @workgroup_size(WG)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(subgroup_id) sid: u32,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(num_subgroups) subgroups: u32,
) {
    let base = (wg.y * p.groups_x + wg.x) * p.c4;
    let shift = f32(x[base].x);
    var s = vec4<f32>(0.0);
    var q = vec4<f32>(0.0);
    for (var i = lid; i < p.c4; i += WG) {
        let d = vec4<f32>(x[base + i]) - shift;
        s += d;
        q += d * d;
    }
    let one = vec4<f32>(1.0);
    let sums = workgroup_sum2(vec2<f32>(dot(s, one), dot(q, one)), sid, lane, subgroups) / f32(4u * p.c4);
    let rstd = inverseSqrt(max(sums.y - sums.x * sums.x, 0.0) + p.eps);
    for (var i = lid; i < p.c4; i += WG) {
        let centred = vec4<f32>(x[base + i]) - shift - sums.x;
        y[base + i] = vec4<S>(centred * rstd * vec4<f32>(gamma[i]) + vec4<f32>(beta[i]));
    }
}
