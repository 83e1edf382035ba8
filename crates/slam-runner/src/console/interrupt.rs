//! Ctrl-C handling of every command: a thread waits for SIGINT ([`handle_interrupts`], installed when a
//! command starts). A command that stops by itself at Ctrl-C (`run`, after [`catch_interrupt`]) sees
//! the first one as a flag it polls ([`interrupted`]) and discards its output; any other Ctrl-C (the
//! first for every other command, a second one for `run`) removes the temporary files and folders the
//! process is writing (`slam_core::files::remove_temporaries`: `.NAME.tmp-PID`, `.DIR.partial-PID`) and
//! ends the process at once (`_exit`) with status 130 and a message. Outputs keep their previous contents either way.

use std::sync::{
    atomic::{AtomicBool, Ordering},
    OnceLock,
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

/// Set by the first Ctrl-C of a command that polls it.
static FLAG: AtomicBool = AtomicBool::new(false);
/// Whether the running command polls [`FLAG`] (set by [`catch_interrupt`]).
static POLLING: AtomicBool = AtomicBool::new(false);
/// Whether the handler thread is installed.
static INSTALLED: OnceLock<bool> = OnceLock::new();

/// Install the Ctrl-C handler (once; every command calls it first): Ctrl-C removes the process's
/// temporary files and folders and ends it with status 130. Without a handler (installation failed)
/// Ctrl-C keeps its default action; temporaries left then are removed by the next command writing the
/// same output.
pub fn handle_interrupts() {
    INSTALLED.get_or_init(|| {
        let signals = signal_hook::iterator::Signals::new([signal_hook::consts::SIGINT]);
        match signals {
            Ok(mut signals) => {
                let spawned = std::thread::Builder::new().name("ctrl-c".into()).spawn(move || {
                    for _ in signals.forever() {
                        // a polling command's first Ctrl-C only asks it to stop
                        if POLLING.load(Ordering::SeqCst) && !FLAG.swap(true, Ordering::SeqCst) {
                            continue;
                        }
                        let removed = slam_core::files::remove_temporaries();
                        eprintln!(
                            "interrupted: Ctrl-C: stopped before the end; {} temporary file(s) or folder(s) removed, \
                             every output keeps its previous contents",
                            removed.len()
                        );
                        // _exit, not exit: the other threads are still running (the detector inside ONNX
                        // Runtime or OpenCV), and the C++ libraries' exit-time destructors would pull their
                        // state from under them: the process then died of a signal instead of ending with
                        // 130. Nothing is left to flush: the message went to unbuffered stderr and the
                        // outputs are kept as they were.
                        signal_hook::low_level::exit(130);
                    }
                });
                spawned.is_ok()
            }
            Err(e) => {
                tracing::warn!("cannot catch Ctrl-C ({e}): it will end the command at once");
                false
            }
        }
    });
}

/// Install the handler for a command that polls [`interrupted`] and stops by itself: the first Ctrl-C
/// sets the flag, a second one ends the process at once (removing its temporaries).
pub fn catch_interrupt() {
    POLLING.store(true, Ordering::SeqCst);
    handle_interrupts();
}

/// Whether Ctrl-C was pressed since [`catch_interrupt`].
pub fn interrupted() -> bool {
    FLAG.load(Ordering::SeqCst)
}
