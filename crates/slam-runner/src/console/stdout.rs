//! Standard output of a command-line program: its `println!`/`print!` write through [`write`], which
//! ends the process quietly when the reader has gone.

use std::io::{ErrorKind, Write};

/// Write `args` to stdout. A closed pipe (`ErrorKind::BrokenPipe`) ends the process with status 0:
/// the reader wanted no more, which is not a failure. Any other write error is a bug in the
/// environment that cannot be reported on stdout; it panics with the error, as `std::println!` does.
pub fn write(args: std::fmt::Arguments<'_>) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args) {
        if e.kind() == ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        panic!("failed printing to stdout: {e}");
    }
}
