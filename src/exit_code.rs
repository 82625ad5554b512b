//! Exit codes a scheduler can act on: 2 for usage and bad input (fix the command, do not
//! retry), 3 for the device (none, lost, hung, refused by `--require-gpu`: another node may
//! do), 4 for a stop that the same command resumes (disk full, interrupted), 1 for anything
//! else. Each library error is classified here, at the edge, by matching every variant, so a
//! new variant cannot go unclassified.

use std::io::ErrorKind;
use vkdiff_formats::Error as FileError;
use vkdiff_runtime::Error as DeviceError;

pub const OTHER: i32 = 1;
pub const USAGE: i32 = 2;
pub const DEVICE: i32 = 3;
pub const RESUMABLE: i32 = 4;

/// The code for `error`: the first cause in its chain that a library or the command line
/// classifies decides it.
pub fn of(error: &anyhow::Error) -> i32 {
    error.chain().find_map(classify).unwrap_or(OTHER)
}

fn classify(cause: &(dyn std::error::Error + 'static)) -> Option<i32> {
    if cause.is::<vkdiff_args::Usage>() {
        return Some(USAGE);
    }
    if let Some(e) = cause.downcast_ref::<vkdiff_dataset::Error>() {
        return Some(dataset(e));
    }
    if let Some(e) = cause.downcast_ref::<vkdiff_pipeline::Error>() {
        return Some(pipeline(e));
    }
    if let Some(e) = cause.downcast_ref::<vkdiff_scenes::Error>() {
        return Some(scenes(e));
    }
    if let Some(e) = cause.downcast_ref::<vkdiff_eval::EvalError>() {
        return Some(eval(e));
    }
    if let Some(e) = cause.downcast_ref::<vkdiff_networks::Error>() {
        return Some(networks(e));
    }
    if let Some(e) = cause.downcast_ref::<vkdiff_lora::Error>() {
        return Some(lora(e));
    }
    if let Some(e) = cause.downcast_ref::<vkdiff_render::RenderError>() {
        return Some(render(e));
    }
    if let Some(e) = cause.downcast_ref::<DeviceError>() {
        return Some(device(e));
    }
    if let Some(e) = cause.downcast_ref::<FileError>() {
        return Some(file(e));
    }
    cause.downcast_ref::<std::io::Error>().map(io)
}

fn dataset(e: &vkdiff_dataset::Error) -> i32 {
    use vkdiff_dataset::Error as E;
    match e {
        E::Config(_) | E::Setting(_) => USAGE,
        E::DiskFull(_) | E::Interrupted(_) => RESUMABLE,
        E::Context(_, inner) => dataset(inner),
        E::File(e) => file(e),
        E::Render(e) => render(e),
        E::Scenes(e) => scenes(e),
        E::Pipeline(e) => pipeline(e),
        E::Eval(e) => eval(e),
    }
}

fn pipeline(e: &vkdiff_pipeline::Error) -> i32 {
    use vkdiff_pipeline::Error as E;
    match e {
        E::Config(_) | E::Setting(_) => USAGE,
        E::NotFinite { .. } => OTHER,
        E::Context(_, inner) => pipeline(inner),
        E::File(e) => file(e),
        E::Network(e) => networks(e),
        E::Lora(e) => lora(e),
        E::Render(e) => render(e),
        E::Runtime(e) => device(e),
    }
}

fn scenes(e: &vkdiff_scenes::Error) -> i32 {
    use vkdiff_scenes::Error as E;
    match e {
        E::Setting(_) => USAGE,
        E::Context(_, inner) => scenes(inner),
        E::Scene(e) => scene(e),
        E::Render(e) => render(e),
    }
}

fn scene(e: &vkdiff_scenes::SceneError) -> i32 {
    use vkdiff_scenes::SceneError as E;
    match e {
        E::Listing(e) | E::Io { source: e, .. } => io(e),
        E::Invalid(_) => USAGE,
    }
}

fn eval(e: &vkdiff_eval::EvalError) -> i32 {
    use vkdiff_eval::EvalError as E;
    match e {
        E::Invalid(_) | E::Setting(_) => USAGE,
        E::File(e) => file(e),
        E::Io { source, .. } => io(source),
        // One image to fix makes the whole run one to fix; else the first image's reason.
        E::Unreadable { errors, .. } if errors.iter().any(|e| file(e) == USAGE) => USAGE,
        E::Unreadable { errors, .. } => errors.first().map_or(USAGE, file),
        E::Network(e) => networks(e),
        E::NotFinite(_) => OTHER,
        E::Context { source, .. } => eval(source),
    }
}

fn networks(e: &vkdiff_networks::Error) -> i32 {
    use vkdiff_networks::Error as E;
    match e {
        E::Checkpoint(_) | E::Config(_) => USAGE,
        E::File(e) => file(e),
        E::Runtime(e) => device(e),
    }
}

fn lora(e: &vkdiff_lora::Error) -> i32 {
    use vkdiff_lora::Error as E;
    match e {
        E::Unsupported { .. } | E::Unmatched { .. } | E::Shape { .. } => USAGE,
        E::Network(e) => networks(e),
        E::File(e) => file(e),
        E::Runtime(e) => device(e),
    }
}

fn render(e: &vkdiff_render::RenderError) -> i32 {
    use vkdiff_render::RenderError as E;
    match e {
        E::Setting(_) | E::OutputExists { .. } | E::TooManyInstances { .. } => USAGE,
        E::Io { error, .. } => io(error),
    }
}

fn device(e: &DeviceError) -> i32 {
    use DeviceError as E;
    match e {
        // What the user named or set wrongly.
        E::BadDeviceIndex { .. } | E::BadDeviceSpec(_) | E::NoSuchDevice { .. } | E::BadSetting(_) => USAGE,
        E::BadVariable(_) => USAGE,
        E::NoValidationLayer => USAGE,
        // The node's device: none, not visible, lost, hung, refused, out of memory, failing.
        E::NoLoader(_) | E::NoDevice | E::NoDriver(_) | E::NotVisible(_) | E::NoGpu(_) | E::Unsupported { .. } => {
            DEVICE
        }
        E::Vulkan { .. } | E::DeviceLost(_) | E::SubmitTimeout { .. } | E::Memory(_) => DEVICE,
        // vkdiff's own mistakes.
        E::Shape(_) | E::NoVariant { .. } => OTHER,
    }
}

fn file(e: &FileError) -> i32 {
    match e {
        FileError::Io { source, .. } => io(source),
        FileError::Format { .. } | FileError::Tensor(_) => USAGE,
    }
}

/// A full disk or quota stops a run that resumes once there is room; a file that is missing,
/// unreadable or in the way is the command's to fix, and so is a file larger than the file
/// system or the job's `ulimit -f` allows (EFBIG, where SIGXFSZ is ignored): no waiting makes
/// room for it.
fn io(e: &std::io::Error) -> i32 {
    match e.kind() {
        ErrorKind::StorageFull | ErrorKind::QuotaExceeded => RESUMABLE,
        ErrorKind::Interrupted => RESUMABLE,
        ErrorKind::FileTooLarge
        | ErrorKind::NotFound
        | ErrorKind::PermissionDenied
        | ErrorKind::AlreadyExists
        | ErrorKind::NotADirectory
        | ErrorKind::IsADirectory
        | ErrorKind::InvalidData
        | ErrorKind::InvalidInput
        | ErrorKind::ReadOnlyFilesystem => USAGE,
        _ => OTHER,
    }
}
