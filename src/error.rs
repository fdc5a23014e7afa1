//! The library's error type.
use std::path::PathBuf;

/// Everything that can go wrong in psrestir, with enough context to act on.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scene, image or task file is unreadable or invalid.
    #[error("{}: {msg}", path.display())]
    File {
        /// The file at fault.
        path: PathBuf,
        /// What is wrong with it.
        msg: String,
    },
    /// No usable GPU adapter.
    #[error("{0}")]
    NoAdapter(String),
    /// The adapter lacks a feature or limit that psrestir needs.
    #[error("GPU adapter unsuitable: {0}")]
    Unsuitable(String),
    /// The GPU ran out of memory.
    #[error(
        "GPU out of memory in {label}: {msg}. Lower the image size (width, height), the \
         texture resolution or the samples per pass, or free GPU memory held by other programs"
    )]
    OutOfMemory {
        /// The pass or buffer involved.
        label: String,
        /// What wgpu reported.
        msg: String,
    },
    /// The GPU device was lost (driver reset, GPU removed, or the device destroyed); nothing
    /// more can run on it.
    #[error(
        "the GPU device was lost in {label}: {msg}. Work on it cannot continue: restart, \
         and continue an optimization from its last checkpoint with `psrestir optimize \
         --resume`; if the driver reset the GPU because a dispatch ran too long, lower the \
         samples per pass or the image size"
    )]
    DeviceLost {
        /// The pass or operation that found the loss.
        label: String,
        /// The reason wgpu gave.
        msg: String,
    },
    /// A GPU operation failed (a validation or internal error).
    #[error(
        "GPU error in {label}: {msg}. This is a bug in psrestir or in the GPU driver; please \
         report it with the output of `psrestir adapter`"
    )]
    Gpu {
        /// The pass or buffer involved.
        label: String,
        /// What wgpu reported.
        msg: String,
    },
    /// A WGSL shader failed to compose or validate.
    #[error("shader {name}: {msg}")]
    Shader {
        /// The pass the shader belongs to.
        name: String,
        /// The parse or validation error.
        msg: String,
    },
    /// An argument is out of range or inconsistent.
    #[error("{0}")]
    Invalid(String),
}

impl Error {
    /// Shorthand for [`Error::File`].
    pub fn file(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::File {
            path: path.into(),
            msg: msg.into(),
        }
    }
}

/// Result with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Run `f`, a decoder working on the file at `path`, turning a panic inside it into
/// [`Error::File`]. Third-party decoders have panicked on malformed files (found by fuzzing,
/// see `tests/fuzz.rs`); a malformed file must give an error, not take the application down.
/// `what` names the decoder in the message. (A build with `panic = "abort"` still aborts.)
pub(crate) fn catch_panic<T>(
    path: &std::path::Path,
    what: &str,
    f: impl FnOnce() -> Result<T>,
) -> Result<T> {
    let was = GUARDED.with(|g| g.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    GUARDED.with(|g| g.set(was));
    result.unwrap_or_else(|p| {
        let msg = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default();
        Err(Error::file(
            path,
            format!("{what} failed on this file ({msg}); the file is malformed or unsupported"),
        ))
    })
}

thread_local! {
    static GUARDED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Whether this thread is running a decoder under psrestir's panic guard, which turns a panic
/// into an [`Error::File`]. An application's panic hook can stay quiet while it is true (the
/// `psrestir` binary's does), since the error will be reported.
pub fn panic_is_guarded() -> bool {
    GUARDED.with(|g| g.get())
}
