//! Progress that shares stderr with the logs: on a terminal an `indicatif` bar, and every log line is
//! written through it (the bar is lifted, the line printed, the bar redrawn); elsewhere (a pipe, a file,
//! CI) plain progress lines at most every few seconds, so a long run still says how far it is.

use std::{
    io::{IsTerminal, Write},
    sync::Mutex,
    time::{Duration, Instant},
};

use indicatif::{ProgressBar, ProgressStyle};

/// The bar on screen, if any: log lines are written around it.
static ACTIVE: Mutex<Option<ProgressBar>> = Mutex::new(None);

/// Seconds between two plain progress lines when stderr is not a terminal.
const PLAIN_EVERY: Duration = Duration::from_secs(5);

/// A log writer for `tracing_subscriber`: collects one event's text and writes it to stderr in one
/// piece, around the progress bar when one is shown.
pub struct LogWriter(Vec<u8>);

impl Write for LogWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for LogWriter {
    fn drop(&mut self) {
        if self.0.is_empty() {
            return;
        }
        let text = std::mem::take(&mut self.0);
        let write = || {
            let _ = std::io::stderr().lock().write_all(&text);
        };
        match ACTIVE.lock().ok().and_then(|g| g.clone()) {
            Some(bar) => bar.suspend(write),
            None => write(),
        }
    }
}

/// `tracing_subscriber` writer factory of [`LogWriter`].
pub fn log_writer() -> LogWriter {
    LogWriter(Vec::new())
}

enum Mode {
    Bar(ProgressBar),
    Plain { last: Instant, start: Instant, pos: u64, message: String },
    Hidden,
}

/// Progress over `len` items of a named unit (`frames`, `sequences`).
pub struct Progress {
    mode: Mode,
    len: u64,
    unit: &'static str,
    label: String,
}

impl Progress {
    /// A bar on a terminal, plain lines otherwise; nothing when `quiet`.
    pub fn new(label: &str, len: u64, unit: &'static str, quiet: bool) -> Self {
        let mode = if quiet {
            Mode::Hidden
        } else if std::io::stderr().is_terminal() {
            let bar = ProgressBar::new(len);
            bar.set_style(
                ProgressStyle::with_template(&format!(
                    "{label} {{bar:40}} {{pos}}/{{len}} {unit} {{per_sec}} eta {{eta}} {{msg}}"
                ))
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            if let Ok(mut g) = ACTIVE.lock() {
                *g = Some(bar.clone());
            }
            Mode::Bar(bar)
        } else {
            let now = Instant::now();
            Mode::Plain { last: now, start: now, pos: 0, message: String::new() }
        };
        Self { mode, len, unit, label: label.to_string() }
    }

    /// A short status shown after the counts (bar) or on the next plain line.
    pub fn set_message(&mut self, text: String) {
        match &mut self.mode {
            Mode::Bar(b) => b.set_message(text),
            Mode::Plain { message, .. } => *message = text,
            Mode::Hidden => {}
        }
    }

    /// A line on stdout that does not tear the bar (stdout and stderr often share a terminal).
    pub fn println(&self, text: &str) {
        match &self.mode {
            Mode::Bar(b) => b.suspend(|| super::stdout::write(format_args!("{text}\n"))),
            _ => super::stdout::write(format_args!("{text}\n")),
        }
    }

    /// One more item done.
    pub fn inc(&mut self) {
        let (len, unit) = (self.len, self.unit);
        match &mut self.mode {
            Mode::Bar(b) => b.inc(1),
            Mode::Plain { last, start, pos, message } => {
                *pos += 1;
                if last.elapsed() >= PLAIN_EVERY || *pos == len {
                    *last = Instant::now();
                    let secs = start.elapsed().as_secs_f64();
                    let rate = *pos as f64 / secs.max(1e-9);
                    let sep = if message.is_empty() { "" } else { "; " };
                    eprintln!("{}: {pos}/{len} {unit} in {secs:.1} s ({rate:.1} {unit}/s){sep}{message}", self.label);
                }
            }
            Mode::Hidden => {}
        }
    }

    /// `done` of `len` items (for work whose total is known only once it runs).
    pub fn set(&mut self, done: u64, len: u64) {
        self.len = len;
        match &mut self.mode {
            Mode::Bar(b) => {
                b.set_length(len);
                b.set_position(done);
            }
            Mode::Plain { pos, .. } if done > *pos => {
                *pos = done - 1;
                self.inc();
            }
            _ => {}
        }
    }

    /// Remove the bar (plain mode has already printed its last line).
    pub fn finish(self) {
        if let Mode::Bar(b) = &self.mode {
            b.finish_and_clear();
            if let Ok(mut g) = ACTIVE.lock() {
                *g = None;
            }
        }
    }
}
