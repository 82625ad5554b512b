// Sinusoidal timestep embedding (diffusers `get_timestep_embedding`): for t = timesteps[b] and
// k < half, a_k = scale · t · exp(-ln(max_period) · k / (half - shift)); the row is
// [sin(a), cos(a)], or [cos(a), sin(a)] when flipped, zero-padded when dim is odd.
@group(0) @binding(0) var<storage, read> timesteps: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<S>;

struct Params {
    dim: u32,
    batch: u32,
    flip: u32,
    shift: f32,
    log_max_period: f32,
    scale: f32,
}

var<immediate> p: Params;

// sin and cos of a large f32 argument: reduce by 2π in two parts (Cody–Waite) first, so the
// result does not depend on the device's accuracy outside [-π, π].
fn reduce(x: f32) -> f32 {
    let n = round(x * 0.15915494309189535);
    return (x - n * 6.28125) - n * 0.0019353071795864769;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= p.dim * p.batch {
        return;
    }
    let b = i / p.dim;
    let j = i % p.dim;
    let half = p.dim / 2u;
    if j >= 2u * half {
        out[i] = S(0.0);
        return;
    }
    let k = j % half;
    let exponent = -p.log_max_period * f32(k) / (f32(half) - p.shift);
    let a = reduce(p.scale * (timesteps[b] * exp(exponent)));
    let second = j >= half;
    let use_cos = (p.flip != 0u) != second;
    out[i] = S(select(sin(a), cos(a), use_cos));
}
