//! Terminal plumbing of a command-line program built on this crate (feature `console`):
//! - [`progress`]: progress that shares stderr with the `tracing` logs (a bar on a terminal, plain lines
//!   every few seconds elsewhere);
//! - [`interrupt`]: Ctrl-C removes the temporaries and ends any command, or is a flag a long command
//!   polls ([`Interrupted`] as its error);
//! - [`stdout`]: stdout that ends the process quietly on a closed pipe (`… | head`);
//! - [`error_text`]: an error and its causes on one line, for the final message;
//! - [`init_logs`]: the `tracing` logs on stderr, beside the progress.

pub mod interrupt;
pub mod progress;
pub mod stdout;

pub use interrupt::{catch_interrupt, handle_interrupts, interrupted, Interrupted};
pub use progress::{log_writer, Progress};

/// Send the `tracing` logs to stderr (through [`log_writer`], so they share it with the progress),
/// filtered by `RUST_LOG` (default `info`), coloured on a terminal only. Once, at the program's start.
pub fn init_logs() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(log_writer)
        .init();
}

/// An error and its whole cause chain on one line, without a backtrace (errors at the command line are
/// about the user's input); a cause that its parent's message already quotes is not repeated.
pub fn error_text(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let c_text = c.to_string();
        if !text.ends_with(&c_text) {
            text = format!("{text}: {c_text}");
        }
        cause = c.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("{0}")]
    struct Outer(String, #[source] std::io::Error);

    #[test]
    fn a_cause_is_appended_unless_already_quoted() {
        let io = || std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        assert_eq!(error_text(&Outer("reading x.json".into(), io())), "reading x.json: no such file");
        assert_eq!(error_text(&Outer("reading x.json: no such file".into(), io())), "reading x.json: no such file");
    }
}
