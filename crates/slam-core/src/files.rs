//! Files at the edge of the system: every reader and every writer of the workspace goes through here.
//!
//! **Reading** ([`read_bytes`], [`read_text`], [`regular_file`]). Only a regular file is read, after
//! following symbolic links: a folder, a named pipe, a device (`/dev/zero`), a socket, or a link that
//! loops or leads nowhere is refused before it is opened, saying what it is, so nothing blocks on a
//! pipe that no one writes and nothing reads an endless device. At most a [`Limit`]'s bytes are read: a
//! larger file is an error that names the limit and its reason (the reader holds the whole text and
//! its parse in memory, so the cap bounds the memory a file can take). Text must be UTF-8 (the error
//! names the line of the first bad byte); a leading byte-order mark, which some editors write, is
//! dropped.
//!
//! **Writing** ([`write_atomic`], [`AtomicWrite`]). A file is written to a temporary sibling
//! `.NAME.tmp-PID`, flushed, and renamed over its destination only when whole. On any failure (a full
//! disk included) the temporary file is removed: a failed write leaves the old file as it was and no
//! temporary file behind. Every temporary is registered while it exists, so that Ctrl-C removes it
//! ([`remove_temporaries`]), and one left by a process that was killed is removed by the next write of
//! the same file ([`remove_stale_temporaries`]). Only a regular file (or a new name) is ever renamed
//! over ([`output_kind`]): a named pipe, or the pipe of a shell's process substitution (`>(gzip > t.gz)`,
//! `/dev/fd/63`), is written into once the contents are whole (a temporary file in the system's
//! temporary folder first), as `cp` and `tee` do; a device (`/dev/null`, a disk), a socket or a folder is
//! refused, saying what it is, and left as it was.

use std::{
    fs::File,
    io::{Read, Write},
    path::{Path, PathBuf},
};

/// How much a reader takes from one file, and why that much.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limit {
    /// Most bytes read.
    pub bytes: u64,
    /// The kind of file, for the message ("a settings file").
    pub what: &'static str,
    /// Why the limit is where it is, for the message.
    pub why: &'static str,
}

const MIB: u64 = 1 << 20;

/// Settings, calibration files, single OXTS packets, a run's `camera.json`, a detector's `.cfg`.
pub const SMALL: Limit = Limit {
    bytes: MIB,
    what: "a settings, calibration or packet file",
    why: "every settings key with its comment is 6 KB, a KITTI calibration file 1-3 KB",
};

/// Per-frame text tables: poses, times, timestamps, labels, trajectories, a run's `tracking.csv`.
pub const TABLE: Limit = Limit {
    bytes: 256 * MIB,
    what: "a per-frame text file (poses, times, labels, trajectories)",
    why: "a pose line is about 200 bytes, so this holds over a million frames, more than a day at 10 Hz",
};

/// JSON documents that grow with a run: maps, detection files, object maps and scores.
pub const DOCUMENT: Limit = Limit {
    bytes: 1024 * MIB,
    what: "a map, detection or object file",
    why: "a map takes about 40 KB per frame of odometry 06, so this holds runs of over 25 000 frames; the parse takes a few times the text in memory",
};

/// Encoded images.
pub const IMAGE: Limit = Limit {
    bytes: 256 * MIB,
    what: "an image",
    why: "an 8-bit colour image of 8192 × 8192 pixels is 192 MiB even uncompressed",
};

/// Detector models (network weights).
pub const MODEL: Limit = Limit {
    bytes: 2048 * MIB,
    what: "a detector model",
    why: "a detector small enough to run per frame on a CPU has well under 100 M weights (400 MB)",
};

/// Optimisation problem files (BAL, g2o).
pub const PROBLEM: Limit = Limit {
    bytes: 1024 * MIB,
    what: "an optimisation problem file",
    why: "the reader holds the text and the problem in memory; the shipped problems are 2-5 MB",
};

/// Why a file could not be read; printed as `cannot read PATH: REASON` ([`ReadError::reason`]).
#[derive(Debug)]
pub enum ReadError {
    /// The file system refused (no such file, no permission, …).
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A symbolic link that loops or leads nowhere.
    BrokenLink {
        /// The link.
        path: PathBuf,
        /// Where it points.
        to: PathBuf,
        /// Why it cannot be followed.
        source: std::io::Error,
    },
    /// Not a regular file.
    NotAFile {
        /// The path.
        path: PathBuf,
        /// What it is ("a folder", "a named pipe", …).
        kind: &'static str,
    },
    /// Larger than the reader takes.
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size (at least this many bytes: a file may grow while it is read).
        size: u64,
        /// The limit.
        limit: Limit,
    },
    /// Not UTF-8 text.
    NotUtf8 {
        /// The file.
        path: PathBuf,
        /// 1-based line of the first invalid byte.
        line: usize,
    },
}

impl ReadError {
    /// The file concerned.
    pub fn path(&self) -> &Path {
        match self {
            ReadError::Io { path, .. }
            | ReadError::BrokenLink { path, .. }
            | ReadError::NotAFile { path, .. }
            | ReadError::TooLarge { path, .. }
            | ReadError::NotUtf8 { path, .. } => path,
        }
    }

    /// Why, without the path: the system's reason (`No such file or directory`), `it is a named pipe,
    /// not a regular file`, …
    pub fn reason(&self) -> String {
        match self {
            ReadError::Io { source, .. } => source.to_string(),
            ReadError::BrokenLink { to, source, .. } => {
                format!("it is a symbolic link to {} that cannot be followed ({source})", to.display())
            }
            ReadError::NotAFile { kind, .. } => format!("it is {kind}, not a regular file"),
            ReadError::TooLarge { size, limit, .. } => format!(
                "it holds {size} bytes, more than the {} read from {} ({})",
                size_text(limit.bytes),
                limit.what,
                limit.why
            ),
            ReadError::NotUtf8 { line, .. } => {
                format!("not UTF-8 text (the first byte that is not is on line {line})")
            }
        }
    }
}

impl std::fmt::Display for ReadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "cannot read {}: {}", self.path().display(), self.reason())
    }
}

impl std::error::Error for ReadError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ReadError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// Check that `path` is a regular file of at most `limit.bytes` ([`regular_file`]), for readers that
/// hand the path to a library (image codecs, network loaders) rather than read it here.
pub fn check_readable(path: &Path, limit: &Limit) -> Result<(), ReadError> {
    let size = regular_file(path)?;
    if size > limit.bytes {
        return Err(ReadError::TooLarge { path: path.to_path_buf(), size, limit: *limit });
    }
    Ok(())
}

/// A byte count as a limit reads: `1 MiB`, `256 MiB`, `1 GiB`.
fn size_text(bytes: u64) -> String {
    if bytes >= 1 << 30 && bytes % (1 << 30) == 0 {
        format!("{} GiB", bytes >> 30)
    } else if bytes >= MIB && bytes % MIB == 0 {
        format!("{} MiB", bytes >> 20)
    } else {
        format!("{bytes} bytes")
    }
}

/// What a path that is not a regular file is, in words.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a folder";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a named pipe";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// Check that `path` is (or links to) a regular file and return its size; the error says what it is
/// instead. Nothing is opened, so a named pipe does not block.
pub fn regular_file(path: &Path) -> Result<u64, ReadError> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(m.len()),
        Ok(m) => Err(ReadError::NotAFile { path: path.to_path_buf(), kind: kind_of(&m) }),
        Err(source) => match std::fs::symlink_metadata(path) {
            // the link exists but cannot be followed
            Ok(l) if l.file_type().is_symlink() => Err(ReadError::BrokenLink {
                path: path.to_path_buf(),
                to: std::fs::read_link(path).unwrap_or_default(),
                source,
            }),
            _ => Err(ReadError::Io { path: path.to_path_buf(), source }),
        },
    }
}

/// The whole of a regular file, at most `limit.bytes` of it ([`regular_file`] first).
pub fn read_bytes(path: &Path, limit: &Limit) -> Result<Vec<u8>, ReadError> {
    check_readable(path, limit)?;
    let io = |source| ReadError::Io { path: path.to_path_buf(), source };
    let file = File::open(path).map_err(io)?;
    // the file was swapped for something else between the check and the open
    let meta = file.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(ReadError::NotAFile { path: path.to_path_buf(), kind: kind_of(&meta) });
    }
    let mut bytes = Vec::with_capacity(meta.len().min(limit.bytes) as usize);
    // one byte more than the limit tells a file that grew past it while being read
    file.take(limit.bytes + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > limit.bytes {
        return Err(ReadError::TooLarge { path: path.to_path_buf(), size: bytes.len() as u64, limit: *limit });
    }
    Ok(bytes)
}

/// The UTF-8 byte-order mark.
const BOM: &str = "\u{feff}";

/// A regular file's text ([`read_bytes`]): UTF-8, a leading byte-order mark dropped.
pub fn read_text(path: &Path, limit: &Limit) -> Result<String, ReadError> {
    let bytes = read_bytes(path, limit)?;
    let mut text = String::from_utf8(bytes).map_err(|e| ReadError::NotUtf8 {
        path: path.to_path_buf(),
        line: 1 + e.as_bytes()[..e.utf8_error().valid_up_to()].iter().filter(|&&b| b == b'\n').count(),
    })?;
    if text.starts_with(BOM) {
        text.drain(..BOM.len());
    }
    Ok(text)
}

/// Why a file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The destination is not something a file can be written to.
    #[error("cannot write {}: {message}", .path.display())]
    Refused {
        /// The destination.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The file system failed (a full disk, no permission, …).
    #[error("cannot write {}: {source}", .path.display())]
    Io {
        /// The destination.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The caller's writer failed.
    #[error("cannot write {}: {source}", .path.display())]
    Writer {
        /// The destination.
        path: PathBuf,
        /// The writer's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// What an output path is, as far as writing it goes ([`output_kind`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputKind {
    /// Nothing yet, or a regular file (also through a symbolic link): written beside it and renamed
    /// over it when whole.
    File,
    /// A named pipe or an anonymous one (`/dev/fd/N`, `/dev/stdout` into a pipe): written into, whole,
    /// never replaced.
    Pipe,
}

/// What `path` is as an output: a new name or a regular file ([`OutputKind::File`]), or a pipe
/// ([`OutputKind::Pipe`]); anything else is refused with what it is. A device is never written: `cp`
/// would write a trajectory onto a disk or into `/dev/mem` as readily as into `/dev/null`, and a rename
/// would replace the device node itself (as root, `/dev/null` for the whole machine); a socket cannot
/// be opened as a file; a folder is not a file name.
pub fn output_kind(path: &Path) -> Result<OutputKind, WriteError> {
    let refuse = |kind: &str| WriteError::Refused {
        path: path.to_path_buf(),
        message: format!(
            "it is {kind}, not a regular file: outputs are written to regular files (or into a pipe), and nothing \
             replaces {kind}; give a file name"
        ),
    };
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(OutputKind::File),
        Ok(m) if m.is_dir() => Err(WriteError::Refused {
            path: path.to_path_buf(),
            message: "it is a folder, expected a file name".into(),
        }),
        #[cfg(unix)]
        Ok(m) if std::os::unix::fs::FileTypeExt::is_fifo(&m.file_type()) => Ok(OutputKind::Pipe),
        Ok(m) => Err(refuse(kind_of(&m))),
        // nothing there yet (or a link to nothing, which the rename replaces): a new file
        Err(_) => Ok(OutputKind::File),
    }
}

/// Temporary files of pipe outputs made by this process so far (their names must differ: two
/// substitutions may both be `/dev/fd/63` in turn).
static PIPE_TEMPORARIES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// A file being written beside its destination: [`AtomicWrite::commit`] renames it into place;
/// dropped without a commit (an error on the way, a panic), the temporary file is removed. A pipe
/// ([`OutputKind::Pipe`]) is written through a temporary file in the system's temporary folder, copied
/// into the pipe on commit.
#[derive(Debug)]
pub struct AtomicWrite {
    path: PathBuf,
    tmp: PathBuf,
    kind: OutputKind,
    done: bool,
}

/// The temporary sibling of `path`: `.NAME.tmp-PID` (hidden; one per process, so two runs writing the
/// same file do not write into each other's temporary).
pub fn temporary_of(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Temporary files and folders this process is writing: what Ctrl-C removes before the process ends
/// ([`remove_temporaries`]), so that no command leaves a `.NAME.tmp-PID` or `.DIR.partial-PID` behind.
static TEMPORARIES: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

fn temporaries() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    TEMPORARIES.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Note a temporary file or folder this process is about to create (call before creating it, so that
/// nothing exists unregistered).
pub fn register_temporary(path: &Path) {
    temporaries().push(path.to_path_buf());
}

/// Forget a temporary that was renamed into place or removed.
pub fn unregister_temporary(path: &Path) {
    temporaries().retain(|p| p != path);
}

/// Remove every registered temporary file and folder, and keep the registry locked from then on: a
/// thread still writing cannot register (so cannot create) another. For the process's last moments
/// (Ctrl-C): returns what was removed.
pub fn remove_temporaries() -> Vec<PathBuf> {
    let mut held = temporaries();
    let removed: Vec<PathBuf> = held
        .drain(..)
        .filter(|p| {
            let meta = std::fs::symlink_metadata(p);
            let gone = match meta {
                Ok(m) if m.is_dir() => std::fs::remove_dir_all(p),
                Ok(_) => std::fs::remove_file(p),
                Err(e) => Err(e),
            };
            gone.is_ok()
        })
        .collect();
    std::mem::forget(held);
    removed
}

/// Whether process `pid` is alive (Linux: `/proc/PID`; elsewhere assumed alive, so nothing is removed).
pub fn process_alive(pid: &str) -> bool {
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid).exists()
    } else {
        true
    }
}

/// Remove temporary siblings of `path` (`.NAME.tmp-PID`) that processes which no longer run left behind
/// (a process killed while writing, or ended by a second Ctrl-C); returns how many.
pub fn remove_stale_temporaries(path: &Path) -> usize {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let prefix = format!(".{name}.tmp-");
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let Ok(entries) = std::fs::read_dir(&dir) else { return 0 };
    let mut removed = 0;
    for e in entries.flatten() {
        let n = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = n.strip_prefix(&prefix) else { continue };
        if pid.chars().all(|c| c.is_ascii_digit()) && pid != std::process::id().to_string() && !process_alive(pid) {
            removed += usize::from(std::fs::remove_file(e.path()).is_ok());
        }
    }
    removed
}

impl AtomicWrite {
    /// Start writing `path`: refuses a folder or a path without a file name, creates the temporary file
    /// (which proves the folder writable: callers make one before the work that fills it). Temporary
    /// siblings left by processes that no longer run are removed first.
    pub fn create(path: &Path) -> Result<Self, WriteError> {
        if path.file_name().is_none() || path.is_dir() {
            return Err(WriteError::Refused {
                path: path.to_path_buf(),
                message: "it is a folder, expected a file name".into(),
            });
        }
        let kind = output_kind(path)?;
        let tmp = match kind {
            OutputKind::File => {
                remove_stale_temporaries(path);
                temporary_of(path)
            }
            // a pipe's folder (`/dev/fd`) takes no file: the contents wait in the temporary folder
            OutputKind::Pipe => {
                let n = PIPE_TEMPORARIES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                std::env::temp_dir().join(format!(".slam-pipe-output-{}-{n}.tmp", std::process::id()))
            }
        };
        register_temporary(&tmp);
        if let Err(source) = File::create(&tmp) {
            unregister_temporary(&tmp);
            return Err(WriteError::Io { path: path.to_path_buf(), source });
        }
        Ok(Self { path: path.to_path_buf(), tmp, kind, done: false })
    }

    /// The temporary file, for writers that take a path (image encoders, plotting libraries).
    pub fn temporary(&self) -> &Path {
        &self.tmp
    }

    /// The destination.
    pub fn destination(&self) -> &Path {
        &self.path
    }

    /// Write the whole contents through `write` (buffered), then put the file in place.
    pub fn write_all_with(self, write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<(), WriteError> {
        let io = |source| WriteError::Io { path: self.path.clone(), source };
        let file = File::create(&self.tmp).map_err(io)?;
        let mut w = std::io::BufWriter::new(file);
        write(&mut w).map_err(io)?;
        let file = w.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(io)?;
        self.commit()
    }

    /// Put the temporary file (written through [`AtomicWrite::temporary`]) in place.
    pub fn commit(mut self) -> Result<(), WriteError> {
        let io = |source| WriteError::Io { path: self.path.clone(), source };
        match self.kind {
            OutputKind::File => {
                if let Ok(f) = File::open(&self.tmp) {
                    // best effort: a crash of the machine, not only of the process
                    let _ = f.sync_all();
                }
                // what was a file when the write started must still be one (or nothing)
                if output_kind(&self.path)? != OutputKind::File {
                    return Err(WriteError::Refused {
                        path: self.path.clone(),
                        message: "it became a pipe while it was written; nothing was written into it".into(),
                    });
                }
                std::fs::rename(&self.tmp, &self.path).map_err(io)?;
            }
            OutputKind::Pipe => {
                // opening waits for a reader, as any writer of a pipe does
                let mut from = File::open(&self.tmp).map_err(io)?;
                let mut to = std::fs::OpenOptions::new().write(true).open(&self.path).map_err(io)?;
                let meta = to.metadata().map_err(io)?;
                if meta.is_file() {
                    return Err(WriteError::Refused {
                        path: self.path.clone(),
                        message: "it was a pipe when the write started and is a file now; nothing was written".into(),
                    });
                }
                std::io::copy(&mut from, &mut to).map_err(io)?;
                to.flush().map_err(io)?;
                drop(from);
                let _ = std::fs::remove_file(&self.tmp);
            }
        }
        self.done = true;
        unregister_temporary(&self.tmp);
        Ok(())
    }
}

impl Drop for AtomicWrite {
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_file(&self.tmp);
            unregister_temporary(&self.tmp);
        }
    }
}

/// Write `bytes` to `path` atomically ([`AtomicWrite`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    AtomicWrite::create(path)?.write_all_with(|w| w.write_all(bytes))
}

/// Where in a JSON document a position lies (`line` and `column`, 1-based, as `serde_json` reports an
/// error): the path of keys and array indices, e.g. `objects[0]` or `frames`; empty at the top. A
/// position on a closing `}` names the object itself (serde reports a missing field there). Text past
/// the end gives the path at the end.
pub fn json_path_at(text: &str, line: usize, column: usize) -> String {
    enum Level {
        Object(Option<String>),
        Array(usize),
    }
    let start = text.split_inclusive('\n').take(line.saturating_sub(1)).map(str::len).sum::<usize>();
    let end = (start + column.saturating_sub(1)).min(text.len());
    let (mut stack, mut expect_key) = (Vec::<Level>::new(), false);
    let mut chars = text.char_indices().peekable();
    while let Some((k, c)) = chars.next() {
        if k >= end {
            if c == '}' {
                if let Some(Level::Object(key)) = stack.last_mut() {
                    *key = None;
                }
            }
            break;
        }
        match c {
            '"' => {
                let mut s = String::new();
                while let Some((_, c)) = chars.next() {
                    match c {
                        // an escaped character is part of the string (a quote does not end it)
                        '\\' => s.extend(chars.next().map(|(_, c)| c)),
                        '"' => break,
                        c => s.push(c),
                    }
                }
                if expect_key {
                    if let Some(Level::Object(key)) = stack.last_mut() {
                        *key = Some(s);
                    }
                    expect_key = false;
                }
            }
            '{' => {
                stack.push(Level::Object(None));
                expect_key = true;
            }
            '[' => stack.push(Level::Array(0)),
            '}' | ']' => {
                stack.pop();
            }
            ',' => match stack.last_mut() {
                Some(Level::Array(i)) => *i += 1,
                Some(Level::Object(_)) => expect_key = true,
                None => {}
            },
            _ => {}
        }
    }
    let mut out = String::new();
    for level in &stack {
        match level {
            Level::Object(Some(key)) => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(key);
            }
            Level::Object(None) => {}
            Level::Array(i) => out.push_str(&format!("[{i}]")),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_json_position_is_named_by_its_path() {
        let t = r#"{"version": 1, "frames": {}}"#;
        assert_eq!(json_path_at(t, 1, 26), "frames");
        let t = "{\"objects\": [\n  {\"id\": 1, \"a\\\"]\": [2, 3]},\n  {\"id\": 2}\n]}";
        // the closing brace of the second object (a missing field is reported there)
        assert_eq!(json_path_at(t, 3, 12), "objects[1]");
        // the 3 in the array under the first object's key with an escaped quote
        assert_eq!(json_path_at(t, 2, 25), "objects[0].a\"][1]");
        assert_eq!(json_path_at(t, 1, 1), "");
    }

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("slam-core-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("scratch");
        d
    }

    fn listing(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .expect("list")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    const TINY: Limit = Limit { bytes: 16, what: "a test file", why: "a test" };

    #[test]
    fn only_regular_files_within_the_limit_are_read() {
        let d = scratch("read");
        let f = d.join("a.txt");
        std::fs::write(&f, "\u{feff}x = 1\n").expect("write");
        assert_eq!(read_text(&f, &TINY).expect("reads"), "x = 1\n", "the byte-order mark is dropped");
        std::fs::write(&f, "0123456789abcdefg").expect("write");
        let e = read_text(&f, &TINY).expect_err("17 bytes").to_string();
        assert!(e.contains("holds 17 bytes") && e.contains("16 bytes read from a test file (a test)"), "{e}");
        let e = read_text(&d, &TINY).expect_err("folder").to_string();
        assert!(e.contains("it is a folder, not a regular file"), "{e}");
        let e = read_bytes(Path::new("/dev/zero"), &TINY).expect_err("device").to_string();
        assert!(e.contains("/dev/zero: it is a character device"), "{e}");
        let e = read_text(&d.join("none"), &TINY).expect_err("missing").to_string();
        assert!(e.starts_with("cannot read") && e.contains("none"), "{e}");
        std::fs::write(&f, b"ok\n\xe9\n").expect("write");
        let e = read_text(&f, &TINY).expect_err("latin-1").to_string();
        assert!(e.contains("not UTF-8 text") && e.contains("line 2"), "{e}");
        #[cfg(unix)]
        {
            let link = d.join("self.png");
            std::os::unix::fs::symlink(&link, &link).expect("self-link");
            let e = read_bytes(&link, &TINY).expect_err("loop").to_string();
            assert!(e.contains("symbolic link") && e.contains("cannot be followed"), "{e}");
            // a named pipe nobody writes: refused at once, not waited on
            let fifo = d.join("pipe");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
            assert!(made, "mkfifo {}", fifo.display());
            let e = read_text(&fifo, &TINY).expect_err("pipe").to_string();
            assert!(e.contains("it is a named pipe"), "{e}");
        }
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let d = scratch("write");
        let f = d.join("x.json");
        write_atomic(&f, b"one").expect("write");
        write_atomic(&f, b"two").expect("write");
        assert_eq!(std::fs::read_to_string(&f).expect("read"), "two");
        let e = AtomicWrite::create(&f)
            .expect("create")
            .write_all_with(|w| {
                w.write_all(b"half")?;
                Err(std::io::Error::other("no space left on device"))
            })
            .expect_err("fails")
            .to_string();
        assert!(e.contains("no space left"), "{e}");
        assert_eq!(std::fs::read_to_string(&f).expect("read"), "two");
        {
            let w = AtomicWrite::create(&f).expect("create");
            std::fs::write(w.temporary(), "three").expect("write");
            // dropped without a commit
        }
        assert_eq!(listing(&d), ["x.json"], "no temporary file left");
        assert!(AtomicWrite::create(&d).expect_err("folder").to_string().contains("is a folder"));
        // the temporary of a file with two extensions keeps its whole name (`.obj.json`, not `.obj.json.json`)
        let t = temporary_of(Path::new("out/x.obj.json"));
        assert_eq!(t, PathBuf::from(format!("out/.x.obj.json.tmp-{}", std::process::id())));
        std::fs::remove_dir_all(&d).ok();
    }

    /// An output that is not a regular file is never renamed over: a named pipe is written into (its
    /// reader gets the whole file and the pipe stays a pipe), a device (reached through a link, so that
    /// nothing outside the scratch folder is at stake) and a socket are refused naming what they are,
    /// and left as they were; a pipe output leaves no temporary file behind.
    #[cfg(unix)]
    #[test]
    fn outputs_go_to_regular_files_or_into_pipes_and_never_replace_devices() {
        use std::os::unix::fs::FileTypeExt;
        let d = scratch("special");
        let fifo = d.join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
        assert!(made, "mkfifo {}", fifo.display());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(&fifo).expect("the reader reads the pipe"))
        };
        assert_eq!(output_kind(&fifo).expect("a pipe is an output"), OutputKind::Pipe);
        write_atomic(&fifo, b"1 0 0 0\n").expect("written into the pipe");
        assert_eq!(reader.join().expect("reader"), b"1 0 0 0\n", "the reader got the whole file");
        assert!(std::fs::symlink_metadata(&fifo).expect("still there").file_type().is_fifo(), "still a pipe");
        let pipe_temporaries = std::fs::read_dir(std::env::temp_dir())
            .expect("temporary folder")
            .flatten()
            .filter(|e| {
                e.file_name().to_string_lossy().starts_with(&format!(".slam-pipe-output-{}-", std::process::id()))
            })
            .count();
        assert_eq!(pipe_temporaries, 0, "the pipe's temporary file is removed");

        let null = d.join("null");
        std::os::unix::fs::symlink("/dev/null", &null).expect("link");
        let e = AtomicWrite::create(&null).expect_err("a device").to_string();
        assert!(e.contains("it is a character device, not a regular file") && e.contains("null"), "{e}");
        assert_eq!(std::fs::read_link(&null).expect("still the link"), PathBuf::from("/dev/null"));
        let socket = d.join("socket");
        let _listener = std::os::unix::net::UnixListener::bind(&socket).expect("socket");
        let e = write_atomic(&socket, b"x").expect_err("a socket").to_string();
        assert!(e.contains("it is a socket, not a regular file"), "{e}");
        assert!(std::fs::symlink_metadata(&socket).expect("still there").file_type().is_socket());
        assert_eq!(listing(&d), ["null", "pipe", "socket"], "no temporary file left, nothing replaced");
        std::fs::remove_dir_all(&d).ok();
    }

    /// A temporary left by a process that no longer runs is removed by the next write of the same file;
    /// one of a live process (this one's, or another's) is not; a live temporary is registered until it
    /// is committed or dropped.
    #[test]
    fn stale_temporaries_are_removed_and_live_ones_registered() {
        let d = scratch("stale");
        let f = d.join("det.json");
        // pid 0 is never a user process; this process's parent is alive
        let dead = d.join(".det.json.tmp-0");
        let parent = d.join(format!(".det.json.tmp-{}", std::os::unix::process::parent_id()));
        let other = d.join(".other.json.tmp-0");
        for p in [&dead, &parent, &other] {
            std::fs::write(p, "left").expect("write");
        }
        let w = AtomicWrite::create(&f).expect("create");
        let mine = w.temporary().to_path_buf();
        assert!(temporaries().contains(&mine), "registered while it exists");
        assert!(!dead.exists(), "a dead process's temporary is removed");
        assert!(parent.exists() && other.exists(), "a live process's, and another file's, are kept");
        w.write_all_with(|out| out.write_all(b"ok")).expect("write");
        assert!(!temporaries().contains(&mine), "unregistered once in place");
        assert_eq!(std::fs::read_to_string(&f).expect("read"), "ok");
        std::fs::remove_dir_all(&d).ok();
    }
}
