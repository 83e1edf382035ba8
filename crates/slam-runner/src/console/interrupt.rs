//! Ctrl-C handling: the first Ctrl-C (SIGINT) sets a flag that long commands poll (they then discard
//! their output); a second one ends the process at once.

use std::sync::{
    atomic::{AtomicBool, Ordering},
    Arc, OnceLock,
};

/// The run was stopped by Ctrl-C; a program's `main` turns it into exit status 130 (128 + SIGINT), as
/// shells do.
#[derive(Debug)]
pub struct Interrupted(pub String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

impl Interrupted {
    /// A command that writes its output folder `out` whole at the end, stopped after `done` frames:
    /// nothing was written, and the folder is as it was (`existed`) or was not created.
    pub fn nothing_written(done: usize, out: &std::path::Path, existed: bool) -> Self {
        let kept = if existed { "keeps the previous run unchanged" } else { "was not created" };
        Interrupted(format!("Ctrl-C after {done} frames: nothing written, {} {kept}", out.display()))
    }
}

static INTERRUPT: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// Install the Ctrl-C handler (once): the first SIGINT sets the flag [`interrupted`] reads, a second one
/// exits at once with status 130. Without a handler (installation failed) Ctrl-C keeps its default
/// action; the output folders stay consistent either way.
pub fn catch_interrupt() {
    INTERRUPT.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        // order matters: the conditional shutdown sees the flag before this SIGINT sets it
        let installed =
            signal_hook::flag::register_conditional_shutdown(signal_hook::consts::SIGINT, 130, flag.clone())
                .and_then(|_| signal_hook::flag::register(signal_hook::consts::SIGINT, flag.clone()));
        if let Err(e) = installed {
            tracing::warn!("cannot catch Ctrl-C ({e}): it will end the run at once (output folders stay consistent)");
        }
        flag
    });
}

/// Whether Ctrl-C was pressed since [`catch_interrupt`].
pub fn interrupted() -> bool {
    INTERRUPT.get().is_some_and(|f| f.load(Ordering::Relaxed))
}
