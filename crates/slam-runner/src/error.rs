//! The one error type of the runner: what went wrong, with the file or option it concerns; a wrapped
//! library error keeps its own message and cause chain (the app prints the chain).

use std::error::Error as StdError;

/// A boxed error of another crate (a detector loader's, an output writer's).
pub type BoxError = Box<dyn StdError + Send + Sync + 'static>;

/// An error of a run, a bench or an inspection.
#[derive(Debug, thiserror::Error)]
pub enum RunnerError {
    /// Input that cannot be used; the message names the option or file and what is wrong.
    #[error("{0}")]
    Invalid(String),
    /// A library error with what was being done (`context: cause` when printed as a chain).
    #[error("{context}")]
    Context {
        /// What was being done, naming the file or case.
        context: String,
        /// The error underneath.
        #[source]
        source: BoxError,
    },
    /// Any other library error, unchanged.
    #[error(transparent)]
    Other(BoxError),
}

/// Result of the runner.
pub type Result<T> = std::result::Result<T, RunnerError>;

impl RunnerError {
    /// Wrap any error unchanged (its message and causes are kept).
    pub fn other(e: impl Into<BoxError>) -> Self {
        RunnerError::Other(e.into())
    }
}

/// Put what was being done in front of a library error.
pub trait Context<T> {
    /// `context()` is evaluated only on error.
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Into<BoxError>> Context<T> for std::result::Result<T, E> {
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| RunnerError::Context { context: context(), source: e.into() })
    }
}

/// Any library error into the runner's, unchanged: `?` on the libraries' results.
macro_rules! from_errors {
    ($($t:ty),*) => {$(
        impl From<$t> for RunnerError {
            fn from(e: $t) -> Self {
                RunnerError::Other(Box::new(e))
            }
        }
    )*};
}

from_errors!(
    slam_dataset::DatasetError,
    slam_dataset::check::CheckError,
    slam_dataset::output::OutputError,
    slam_frontend::FrontendError,
    slam_detect::ModelError,
    slam_frontend::image_size::ImageSizeError,
    slam_pipeline::system::SystemError,
    slam_pipeline::saved_map::SavedMapError,
    slam_eval::EvalError,
    slam_viz::VizError,
    slam_pipeline::settings::SettingsError,
    slam_core::check::InvalidValue,
    slam_core::files::WriteError,
    std::io::Error
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_keeps_the_cause_and_other_keeps_the_message() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = Err::<(), _>(io).context_with(|| "reading x.json".into()).expect_err("error");
        assert_eq!(e.to_string(), "reading x.json");
        assert_eq!(e.source().map(|s| s.to_string()).as_deref(), Some("no such file"));
        let o = RunnerError::other(std::io::Error::other("disk full"));
        assert_eq!(o.to_string(), "disk full");
    }
}
