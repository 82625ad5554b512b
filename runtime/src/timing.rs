//! What a timed recording reports of each dispatch.

/// Time one dispatch took on the device.
#[derive(Clone, Debug)]
pub struct Timing {
    pub kernel: &'static str,
    pub nanos: f64,
}
