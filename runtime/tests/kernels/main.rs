//! Every kernel against an f64 CPU reference on the Vulkan device (lavapipe in CI), for f32 and
//! f16 storage, with the tolerance each test states.

mod attention;
mod attention_cm2;
mod bands;
mod ceiling;
mod conv;
mod conv_cm2;
mod elementwise;
mod gemm;
mod linear_cm2;
mod matrix_unit_trial;
mod norm;
mod pool;
mod runtime;
mod tuning;
