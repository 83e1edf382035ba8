//! ONNX models on ONNX Runtime, through the `ort` crate with its `load-dynamic` feature: nothing of the
//! runtime is linked or downloaded at build time; its shared library is opened when the first ONNX model
//! is loaded ([`OnnxNet::load`]).
//!
//! **Where the library comes from** ([`runtime_library`]): the environment variable `ORT_DYLIB_PATH`
//! (`ort`'s own name for it) when it is set, else the path `tools/setup.sh` recorded in its folder
//! (`.ort/` at the repository's root: `cpu.path` for the official `onnxruntime` wheel's
//! `libonnxruntime.so`, `gpu.path` for the `onnxruntime-gpu` wheel's). Without either, loading fails with
//! an error that says how to get it, never a panic.
//!
//! **One runtime per process.** A process can open one ONNX Runtime library; asking for a second one
//! (another path) is an error naming both, not a silent use of the first.
//!
//! **Devices.** [`Device::Cpu`] runs ONNX Runtime's CPU provider with [`RuntimeOptions::threads`]
//! intra-op threads. [`Device::Cuda`] registers the CUDA execution provider, which only the
//! `onnxruntime-gpu` runtime has; a runtime without it, or a machine without a usable GPU, is an error.

use std::{
    path::{Path, PathBuf},
    sync::{Mutex, PoisonError},
    time::Instant,
};

use ort::{
    environment::Environment,
    ep::{ExecutionProvider, CUDA},
    session::Session,
    value::TensorRef,
};

/// The environment variable naming the ONNX Runtime library to open (the name the `ort` crate uses).
pub const ORT_DYLIB_PATH: &str = "ORT_DYLIB_PATH";

/// The oldest ONNX Runtime this build can use. `ort` asks the library for the C API of its baseline level,
/// 17, because no `api-*` feature is enabled: nothing newer is used, so any runtime from 1.17 on serves
/// (docs/detections.md, "ONNX Runtime").
pub const MIN_RUNTIME: &str = "1.17";

/// Intra-op threads of a CPU session by default: one. On two cores the detector shares the machine with
/// tracking (ORB extraction already spreads over both) and local mapping; a second intra-op thread made the
/// forward pass faster alone but the main job no faster and its tracking slower (docs/detections.md, "Thread
/// budget", measured with `run-bench`).
pub const DEFAULT_THREADS: usize = 1;

/// Most intra-op threads accepted: ONNX Runtime starts one OS thread per intra-op thread beyond the caller's,
/// and a detector this small has no work for more (a typo of 1000 would start 1000 threads).
pub const MAX_THREADS: usize = 64;

/// The intra-op threads a CPU session runs with for `asked`: at most the cores this process may use
/// (`std::thread::available_parallelism`). More threads than cores only wait on each other: 64 threads
/// on 2 cores ran the shipped detector at 0.6 frames/s against 50 with one. `None` when `asked` fits.
pub fn capped_threads(asked: usize) -> Option<usize> {
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    (asked > cores).then_some(cores)
}

/// Where a network runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Device {
    /// ONNX Runtime's CPU provider (the default).
    #[default]
    Cpu,
    /// ONNX Runtime's CUDA execution provider (the `onnxruntime-gpu` runtime and an NVIDIA GPU).
    Cuda,
}

impl Device {
    /// Lower-case name, as on a command line.
    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Cuda => "cuda",
        }
    }

    /// The file in the setup folder that holds this device's runtime library path.
    fn record(self) -> &'static str {
        match self {
            Device::Cpu => "cpu.path",
            Device::Cuda => "gpu.path",
        }
    }

    /// The wheel that brings this device's runtime.
    fn wheel(self) -> &'static str {
        match self {
            Device::Cpu => "onnxruntime",
            Device::Cuda => "onnxruntime-gpu",
        }
    }
}

/// How ONNX models are run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RuntimeOptions {
    /// The device.
    pub device: Device,
    /// Intra-op threads of a CPU session (ignored on CUDA, where the GPU does the work).
    pub threads: usize,
    /// The folder where `tools/setup.sh` records the runtime libraries (`.ort/` at the repository's root).
    pub setup_dir: PathBuf,
}

impl RuntimeOptions {
    /// The CPU with [`DEFAULT_THREADS`], the runtime recorded in `setup_dir`.
    pub fn cpu(setup_dir: impl Into<PathBuf>) -> Self {
        Self { device: Device::Cpu, threads: DEFAULT_THREADS, setup_dir: setup_dir.into() }
    }
}

/// Errors of ONNX Runtime: finding and opening its library, loading a model, running it.
#[derive(Debug, thiserror::Error)]
pub enum OnnxError {
    /// Neither `ORT_DYLIB_PATH` nor a path recorded by the setup.
    #[error(
        "ONNX Runtime is not installed: {ORT_DYLIB_PATH} is not set and {record} does not exist. Run `bash \
         tools/setup.sh`: it installs the official `{wheel}` wheel into a virtual environment in {dir} and records \
         its libonnxruntime.so in {record}{gpu_note}; or set {ORT_DYLIB_PATH} to a libonnxruntime.so of ONNX \
         Runtime {MIN_RUNTIME} or newer"
    )]
    NotInstalled {
        /// The setup folder.
        dir: PathBuf,
        /// The record that was looked for.
        record: PathBuf,
        /// The wheel that brings the runtime.
        wheel: &'static str,
        /// When the setup installs it (the GPU runtime: only where a GPU is found).
        gpu_note: &'static str,
    },
    /// The library named does not exist.
    #[error(
        "the ONNX Runtime library {path} ({origin}) does not exist: run `bash tools/setup.sh` to install the \
         runtime, or set {ORT_DYLIB_PATH} to a libonnxruntime.so of ONNX Runtime {MIN_RUNTIME} or newer"
    )]
    MissingLibrary {
        /// The path.
        path: PathBuf,
        /// Where the path came from.
        origin: String,
    },
    /// The library exists but does not open as ONNX Runtime (not a library, another library, too old).
    #[error(
        "the ONNX Runtime library {path} does not load: {message} (ONNX Runtime {MIN_RUNTIME} or newer is needed)"
    )]
    Load {
        /// The library.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// A second, different runtime library asked for in one process.
    #[error("ONNX Runtime is already loaded from {loaded} in this process; {wanted} cannot be loaded beside it")]
    AlreadyLoaded {
        /// The library loaded.
        loaded: PathBuf,
        /// The library asked for.
        wanted: PathBuf,
    },
    /// Device CUDA with a runtime that has no CUDA execution provider.
    #[error(
        "device cuda: the ONNX Runtime at {path} has no CUDA execution provider (it is a CPU build); the \
         `onnxruntime-gpu` wheel's runtime has it (tools/setup.sh installs it where nvidia-smi lists a GPU, or with \
         SLAM_ORT_GPU=1)"
    )]
    NoCudaProvider {
        /// The runtime library.
        path: PathBuf,
    },
    /// The CUDA execution provider did not start (no GPU, no driver, CUDA libraries missing).
    #[error("device cuda: the CUDA execution provider did not start (an NVIDIA GPU with its driver is needed): {0}")]
    Cuda(String),
    /// The model does not load.
    #[error("ONNX Runtime cannot load the model {path}: {message}")]
    Model {
        /// The model file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// A forward pass failed, or its output is not one float tensor.
    #[error("ONNX Runtime: {0}")]
    Run(String),
}

/// The ONNX Runtime library to open for `device`: `env` (the value of `ORT_DYLIB_PATH`) when it is set and
/// not empty, else the path recorded in `setup_dir` (`cpu.path`, `gpu.path`). The file must exist.
pub fn runtime_library(env: Option<&std::ffi::OsStr>, device: Device, setup_dir: &Path) -> Result<PathBuf, OnnxError> {
    let (path, origin) = match env.filter(|v| !v.is_empty()) {
        Some(v) => (PathBuf::from(v), format!("from {ORT_DYLIB_PATH}")),
        None => {
            let record = setup_dir.join(device.record());
            let text = match std::fs::read_to_string(&record) {
                Ok(t) => t,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    let gpu_note = match device {
                        Device::Cpu => "",
                        Device::Cuda => " (only where nvidia-smi lists a GPU, or with SLAM_ORT_GPU=1)",
                    };
                    return Err(OnnxError::NotInstalled {
                        dir: setup_dir.to_path_buf(),
                        record,
                        wheel: device.wheel(),
                        gpu_note,
                    });
                }
                Err(e) => {
                    return Err(OnnxError::Load { path: record, message: format!("cannot read this record: {e}") })
                }
            };
            if text.trim().is_empty() {
                return Err(OnnxError::Load {
                    path: record,
                    message: "this record of the runtime library is empty: run `bash tools/setup.sh` again (it writes \
                              the library's path there)"
                        .into(),
                });
            }
            (PathBuf::from(text.trim()), format!("recorded in {}", record.display()))
        }
    };
    match std::fs::metadata(&path) {
        Ok(m) if m.is_file() => Ok(path),
        Ok(m) => Err(OnnxError::Load {
            path,
            message: format!(
                "it is {} ({origin}), not a library file",
                if m.is_dir() { "a folder" } else { "not a regular file" }
            ),
        }),
        Err(_) => Err(OnnxError::MissingLibrary { path, origin }),
    }
}

/// The library this process opened and its environment (ONNX Runtime allows one of each per process).
static RUNTIME: Mutex<Option<(PathBuf, Option<Environment>)>> = Mutex::new(None);

/// Open the runtime library `path` (once per process) and start its environment, as loading a model
/// does first: an error when it is not an ONNX Runtime this build can use (not a library, too old, no
/// API table behind its entry point).
pub fn open_runtime(path: &Path) -> Result<(), OnnxError> {
    environment(path).map(|_| ())
}

/// Open the runtime library `path` (once per process) and its environment.
fn environment(path: &Path) -> Result<Environment, OnnxError> {
    let path = std::fs::canonicalize(path)
        .map_err(|e| OnnxError::MissingLibrary { path: path.to_path_buf(), origin: e.to_string() })?;
    let mut runtime = RUNTIME.lock().unwrap_or_else(PoisonError::into_inner);
    let load = |message: String| OnnxError::Load { path: path.clone(), message };
    match &*runtime {
        Some((loaded, _)) if *loaded != path => {
            return Err(OnnxError::AlreadyLoaded { loaded: loaded.clone(), wanted: path.clone() })
        }
        Some((_, Some(env))) => return Ok(env.clone()),
        Some((_, None)) => return Err(load("its environment failed to start earlier in this process".into())),
        None => {}
    }
    let no_table = |m: String| {
        load(format!(
            "it exports ONNX Runtime's entry point OrtGetApiBase but gives no usable API table through it (the `ort` \
             crate: {m})"
        ))
    };
    let builder = unpanicked(|| ort::init_from(&path)).map_err(no_table)?.map_err(|e| load(load_message(&e)))?;
    // from here the library stays open whatever follows: remember it, so no other one is tried beside it
    *runtime = Some((path.clone(), None));
    // the environment is the first call through the API table (`ort` asks the library for it here)
    let env =
        unpanicked(|| builder.with_name("quadric-slam").build()).map_err(no_table)?.map_err(|e| load(e.to_string()))?;
    *runtime = Some((path.clone(), Some(env.clone())));
    tracing::debug!(library = %path.display(), "ONNX Runtime loaded");
    Ok(env)
}

thread_local! {
    /// This thread is in [`unpanicked`]: a panic here is its error, not a message for the user.
    static GUARDED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run `f`, a call into `ort` that checks what the runtime library hands it by panicking (`OrtGetApiBase`
/// returning nothing, an API table of the version asked for missing: `ort` asserts, it does not return
/// an error), and give such a panic back as an error with its message, printed by no one. The panic
/// hook that keeps it quiet is installed once and leaves every other panic, and panics of other
/// threads, to the hook before it.
fn unpanicked<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    static QUIET_HOOK: std::sync::Once = std::sync::Once::new();
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !GUARDED.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    GUARDED.with(|g| g.set(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    GUARDED.with(|g| g.set(false));
    result.map_err(|p| {
        p.downcast_ref::<&str>()
            .map(|m| m.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "it panicked".into())
    })
}

/// Why the library did not open, with the system loader's own reason (`ort` names only the call that failed).
fn load_message(e: &ort::LoadDynamicError) -> String {
    let mut message = e.to_string();
    if let ort::LoadDynamicError::Dlopen { error, .. } = e {
        let mut cause = std::error::Error::source(error);
        while let Some(c) = cause {
            message.push_str(&format!(": {c}"));
            cause = c.source();
        }
    }
    message
}

/// An ONNX model in an ONNX Runtime session, with the time of its forward passes.
pub struct OnnxNet {
    session: Session,
    device: Device,
    /// Milliseconds spent in forward passes since [`OnnxNet::take_forward_ms`] was last called.
    forward_ms: f64,
}

impl std::fmt::Debug for OnnxNet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxNet").field("device", &self.device).finish_non_exhaustive()
    }
}

impl OnnxNet {
    /// Load `model` on the runtime `options` name (opened first if this process has not yet).
    pub fn load(model: &Path, options: &RuntimeOptions) -> Result<Self, OnnxError> {
        let env_var = std::env::var_os(ORT_DYLIB_PATH);
        let library = runtime_library(env_var.as_deref(), options.device, &options.setup_dir)?;
        let env = environment(&library)?;
        let model_error = |message: String| OnnxError::Model { path: model.to_path_buf(), message };
        let mut builder = Session::builder(&env).map_err(|e| model_error(e.to_string()))?;
        builder = match options.device {
            Device::Cpu => {
                let mut threads = options.threads.max(1);
                if let Some(cores) = capped_threads(threads) {
                    tracing::warn!(
                        "detector_threads {threads}: this process may use {cores} cores, and intra-op threads beyond them only wait on each other: {cores} used"
                    );
                    threads = cores;
                }
                builder.with_intra_threads(threads).map_err(|e| model_error(e.to_string()))?
            }
            Device::Cuda => {
                if !CUDA::is_available().map_err(|e| OnnxError::Cuda(e.to_string()))? {
                    return Err(OnnxError::NoCudaProvider { path: library });
                }
                preload_cuda_libraries(&options.setup_dir);
                let cuda = CUDA::default().build().error_on_failure();
                builder.with_execution_providers([cuda]).map_err(|e| OnnxError::Cuda(e.to_string()))?
            }
        };
        let session = builder.commit_from_file(model).map_err(|e| model_error(e.to_string()))?;
        if session.inputs().len() != 1 || session.outputs().is_empty() {
            return Err(model_error(format!(
                "a detector has one input (an image) and at least one output; this model has {} inputs and {} outputs",
                session.inputs().len(),
                session.outputs().len()
            )));
        }
        Ok(Self { session, device: options.device, forward_ms: 0.0 })
    }

    /// The device it runs on.
    pub fn device(&self) -> Device {
        self.device
    }

    /// Run the network on one `1 × 3 × height × width` image blob (`input`, row-major) and hand the first
    /// output's shape and values to `read`.
    pub fn forward<R>(
        &mut self,
        input: &[f32],
        [width, height]: [usize; 2],
        read: impl FnOnce(&[i64], &[f32]) -> R,
    ) -> Result<R, OnnxError> {
        let run = |e: ort::Error| OnnxError::Run(e.to_string());
        let start = Instant::now();
        let tensor = TensorRef::from_array_view(([1usize, 3, height, width], input)).map_err(run)?;
        let outputs = self.session.run(ort::inputs![tensor]).map_err(run)?;
        let (shape, values) = outputs[0].try_extract_tensor::<f32>().map_err(run)?;
        self.forward_ms += start.elapsed().as_secs_f64() * 1e3;
        Ok(read(shape, values))
    }

    /// The forward passes' time since the last call, ms (and restart the count).
    pub fn take_forward_ms(&mut self) -> f64 {
        std::mem::take(&mut self.forward_ms)
    }
}

/// Open the CUDA and cuDNN libraries of the `onnxruntime-gpu` wheel's `nvidia-*` dependencies before the
/// CUDA provider looks for them: they are not on the loader's search path (the wheel's Python side opens
/// them itself). `tools/setup.sh` lists their folders in `gpu.libs`, one a line. A library is opened once
/// the ones it needs are (tried again until no more open); one that does not open is logged, and the
/// provider's own start then says what is missing.
fn preload_cuda_libraries(setup_dir: &Path) {
    let Ok(list) = std::fs::read_to_string(setup_dir.join("gpu.libs")) else { return };
    let mut pending: Vec<PathBuf> = list
        .lines()
        .filter(|l| !l.trim().is_empty())
        .filter_map(|dir| std::fs::read_dir(dir.trim()).ok())
        .flat_map(|entries| entries.flatten().map(|e| e.path()))
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("lib") && n.contains(".so")))
        .collect();
    pending.sort();
    loop {
        let before = pending.len();
        pending.retain(|p| ort::util::preload_dylib(p).is_err());
        if pending.is_empty() || pending.len() == before {
            break;
        }
    }
    for p in &pending {
        tracing::debug!(library = %p.display(), "a CUDA library did not open");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_library_comes_from_the_variable_or_the_setup_record_and_must_exist() {
        let dir = std::env::temp_dir().join(format!("ort-setup-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        // nothing recorded: the error says how to install it
        let e = runtime_library(None, Device::Cpu, &dir).expect_err("not installed").to_string();
        assert!(e.contains("bash tools/setup.sh") && e.contains("ORT_DYLIB_PATH") && e.contains("cpu.path"), "{e}");
        let e = runtime_library(None, Device::Cuda, &dir).expect_err("no GPU runtime").to_string();
        assert!(e.contains("onnxruntime-gpu") && e.contains("gpu.path"), "{e}");
        // a wrong path, from the variable or from the record, is named with where it came from
        let wrong = std::ffi::OsStr::new("/no/such/libonnxruntime.so");
        let e = runtime_library(Some(wrong), Device::Cpu, &dir).expect_err("missing").to_string();
        assert!(e.contains("/no/such/libonnxruntime.so (from ORT_DYLIB_PATH) does not exist"), "{e}");
        std::fs::write(dir.join("cpu.path"), "/no/such/recorded.so\n").expect("record");
        let e = runtime_library(None, Device::Cpu, &dir).expect_err("stale record").to_string();
        assert!(e.contains("/no/such/recorded.so (recorded in") && e.contains("tools/setup.sh"), "{e}");
        // an existing file passes (whether it is a runtime is for the loader to say); an empty variable is unset
        let lib = dir.join("libonnxruntime.so");
        std::fs::write(&lib, b"not a library").expect("file");
        std::fs::write(dir.join("cpu.path"), format!("{}\n", lib.display())).expect("record");
        assert_eq!(runtime_library(Some(std::ffi::OsStr::new("")), Device::Cpu, &dir).expect("recorded"), lib);
        assert_eq!(runtime_library(Some(lib.as_os_str()), Device::Cuda, &dir).expect("variable"), lib);
        // a folder is said to be one, not to be missing; an empty record is said to be empty
        let e = runtime_library(Some(dir.as_os_str()), Device::Cpu, &dir).expect_err("a folder").to_string();
        assert!(e.contains("it is a folder (from ORT_DYLIB_PATH), not a library file"), "{e}");
        std::fs::write(dir.join("cpu.path"), "\n").expect("record");
        let e = runtime_library(None, Device::Cpu, &dir).expect_err("empty record").to_string();
        assert!(e.contains("cpu.path does not load: this record of the runtime library is empty"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Intra-op threads are capped at the cores the process may use (more only wait on each other).
    #[test]
    fn detector_threads_are_capped_at_the_cores() {
        let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
        assert_eq!(capped_threads(1), None);
        assert_eq!(capped_threads(cores), None);
        assert_eq!(capped_threads(cores + 1), Some(cores));
        assert_eq!(capped_threads(MAX_THREADS.max(cores + 1)), Some(cores));
    }
}
