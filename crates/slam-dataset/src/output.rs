//! Output that is never half-written (used by `slam-app`'s commands; errors are [`OutputError`]).
//!
//! * [`OutputDir`]: a command that writes a folder (`run --out`, `sim --out`, `detect --overlays`) writes
//!   into a temporary sibling (`.NAME.partial-PID`) and puts it in place only when everything is written:
//!   on Linux by swapping the two folders in one step (`renameat2(RENAME_EXCHANGE)`), elsewhere by
//!   renaming the old folder to a backup (`.NAME.old-PID`), the new one into place, then removing the
//!   backup. A run killed at any point leaves `NAME` as it was or as the finished run wrote it, never a
//!   mixture; a finished run leaves no file of an earlier one.
//! * [`write_file`] / [`AtomicFile`]: a single file is written beside its destination and renamed over it;
//!   folders made for it are removed again when it is not written.
//! * [`FilesInto`]: files written into a folder that may hold others (`map --picture DIR`) replace only
//!   files this program wrote there (the marker lists them), and are recorded in the marker.
//!
//! Folders are replaced as a whole, so a folder is only replaced when this program wrote it: it is empty,
//! or every entry is one its marker file (`.slam-app-output`, written last) lists. Anything else (a folder
//! without the marker, even one holding only names the command writes) is refused before any work
//! starts, naming the foreign entries.

use std::path::{Path, PathBuf};

/// Errors of the output helpers; each message names the path (and the command-line option, where given).
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The destination cannot be used as asked (a file where a folder is needed, foreign entries, …).
    #[error("{0}")]
    Refused(String),
    /// A file-system operation failed.
    #[error("{context}: {source}")]
    Io {
        /// What was being done, naming the path.
        context: String,
        /// Why.
        source: std::io::Error,
    },
    /// The caller's writer failed.
    #[error("{context}: {source}")]
    Writer {
        /// What was being written.
        context: String,
        /// The writer's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The caller's writer failed (its error as it is).
    #[error("{0}")]
    Callback(#[source] Box<dyn std::error::Error + Send + Sync>),
}

/// Result of the output helpers.
pub type Result<T> = std::result::Result<T, OutputError>;

macro_rules! bail {
    ($($arg:tt)*) => {
        return Err(OutputError::Refused(format!($($arg)*)))
    };
}

/// Attach a message to an I/O error.
trait Context<T> {
    fn with_context(self, f: impl FnOnce() -> String) -> Result<T>;
}

impl<T> Context<T> for std::io::Result<T> {
    fn with_context(self, f: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|source| OutputError::Io { context: f(), source })
    }
}

/// Name of the marker file listing what a command wrote into its output folder.
pub const MARKER: &str = ".slam-app-output";

/// `dir`'s parent (`.` for a bare name) and file name; refuses paths without a name (`.`, `/`, `..`).
fn split(dir: &Path, option: &str) -> Result<(PathBuf, String)> {
    let name = match dir.file_name() {
        Some(n) if dir.components().next_back().is_some_and(|c| matches!(c, std::path::Component::Normal(_))) => {
            n.to_string_lossy().into_owned()
        }
        _ => bail!(
            "{option} {}: name a folder of its own (it is replaced as a whole), not `.`, `..` or `/`",
            dir.display()
        ),
    };
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((parent, name))
}

/// Whether process `pid` is alive (Linux: `/proc/PID`; elsewhere assumed alive, so nothing is removed).
fn alive(pid: &str) -> bool {
    slam_core::files::process_alive(pid)
}

/// Clear up what killed runs left beside `dir`: their temporary folders, and a backup whose swap was cut short.
fn remove_leftovers(dir: &Path, parent: &Path, name: &str, pid: u32) -> Result<()> {
    let partial = format!(".{name}.partial-");
    let old = format!(".{name}.old-");
    let mut backups = Vec::new();
    if let Ok(rd) = std::fs::read_dir(parent) {
        for e in rd.flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            if let Some(p) = n.strip_prefix(&partial) {
                if p != pid.to_string() && !alive(p) {
                    let _ = std::fs::remove_dir_all(e.path());
                    tracing::info!("removed {} (left by a run that was killed)", e.path().display());
                }
            } else if let Some(p) = n.strip_prefix(&old) {
                if !alive(p) {
                    backups.push(e.path());
                }
            }
        }
    }
    backups.sort();
    for b in backups {
        if !dir.exists() {
            std::fs::rename(&b, dir).with_context(|| format!("cannot restore {} to {}", b.display(), dir.display()))?;
            tracing::warn!(
                "{}: restored the previous output from {} (a run was killed while replacing it)",
                dir.display(),
                b.display()
            );
        } else {
            let _ = std::fs::remove_dir_all(&b);
        }
    }
    Ok(())
}

/// Refuse an existing `dir` that is a file or holds entries its marker does not list (or has no marker).
fn check_replaceable(dir: &Path, option: &str, command: &str) -> Result<()> {
    let meta = std::fs::metadata(dir).with_context(|| format!("{option} {}", dir.display()))?;
    if !meta.is_dir() {
        bail!("{option} {}: is a file, not a folder", dir.display());
    }
    let listed: Vec<String> = slam_core::files::read_text(&dir.join(MARKER), &slam_core::files::SMALL)
        .map(|t| t.lines().skip(1).map(str::to_string).collect())
        .unwrap_or_default();
    let marked = dir.join(MARKER).is_file();
    let mut foreign: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("{option} {}: cannot list it", dir.display()))?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n != MARKER && !(marked && listed.contains(n)))
        .collect();
    foreign.sort();
    if !foreign.is_empty() && !marked {
        let shown: Vec<&str> = foreign.iter().take(5).map(String::as_str).collect();
        bail!(
            "{option} {}: holds {} entr{} ({}{}) and no `{MARKER}` file, so `slam-app {command}` did not \
             write it: the folder is replaced as a whole, so choose a new or empty folder",
            dir.display(),
            foreign.len(),
            if foreign.len() == 1 { "y" } else { "ies" },
            shown.join(", "),
            if foreign.len() > 5 { ", …" } else { "" }
        );
    }
    if !foreign.is_empty() {
        let shown: Vec<&str> = foreign.iter().take(5).map(String::as_str).collect();
        bail!(
            "{option} {}: holds {} entr{} that `slam-app {command}` did not write ({}{}): the folder is \
             replaced as a whole, so choose a new or empty folder or move them away",
            dir.display(),
            foreign.len(),
            if foreign.len() == 1 { "y" } else { "ies" },
            shown.join(", "),
            if foreign.len() > 5 { ", …" } else { "" }
        );
    }
    Ok(())
}

/// A folder being written: files go into [`OutputDir::path`]; [`OutputDir::commit`] puts it in place.
/// Dropped without a commit, the temporary folder is removed and the old folder is untouched.
pub struct OutputDir {
    target: PathBuf,
    tmp: PathBuf,
    parent: PathBuf,
    name: String,
    done: bool,
}

impl OutputDir {
    /// Prepare `dir` (named `option` in messages, e.g. `--out`) for a command: checks that `dir` is new,
    /// empty, or a folder this program wrote (every entry listed in its marker), recovers from an
    /// interrupted replacement, removes temporary folders of dead runs, and creates the temporary folder
    /// (which also proves the location writable, before any work starts). A folder without the marker is
    /// never replaced, even when its files have the names the command writes: a user's own `map.json` or
    /// a camera's image folder looks the same.
    pub fn create(dir: &Path, option: &str, command: &str) -> Result<Self> {
        let (parent, name) = split(dir, option)?;
        create_folder(&parent).map_err(|e| {
            OutputError::Refused(format!("{option} {}: cannot create its parent folder: {e}", dir.display()))
        })?;
        let pid = std::process::id();
        let partial = format!(".{name}.partial-");
        remove_leftovers(dir, &parent, &name, pid)?;
        if std::fs::symlink_metadata(dir).is_ok_and(|m| m.file_type().is_symlink()) {
            // swapping would replace the link, not the folder it points to
            bail!("{option} {}: is a symbolic link; give the folder it points to", dir.display());
        }
        if dir.exists() {
            check_replaceable(dir, option, command)?;
        }
        let tmp = parent.join(format!("{partial}{pid}"));
        let _ = std::fs::remove_dir_all(&tmp);
        // registered first: Ctrl-C removes it (`slam_core::files::remove_temporaries`)
        slam_core::files::register_temporary(&tmp);
        if let Err(e) = std::fs::create_dir(&tmp) {
            slam_core::files::unregister_temporary(&tmp);
            return Err::<Self, _>(e).with_context(|| {
                format!("{option} {}: cannot write in {} (checked before starting)", dir.display(), parent.display())
            });
        }
        // from here on the temporary folder is this value's: dropped on an error, it is removed (a
        // full disk fails the probe below, and must not keep the folder)
        let out = Self { target: dir.to_path_buf(), tmp, parent, name, done: false };
        let probe = out.tmp.join(MARKER);
        std::fs::write(&probe, format!("slam-app {command}\n")).with_context(|| {
            format!("{option} {}: cannot write in {} (checked before starting)", dir.display(), out.parent.display())
        })?;
        Ok(out)
    }

    /// Where to write (the temporary folder).
    pub fn path(&self) -> &Path {
        &self.tmp
    }

    /// The folder the output will be at.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Put the written folder in place of the old one (which is removed), in one step where the system
    /// allows it.
    pub fn commit(mut self) -> Result<()> {
        // the marker is written last: it lists every entry, so a later run knows what it may replace
        let mut names: Vec<String> = std::fs::read_dir(&self.tmp)
            .with_context(|| format!("cannot list {}", self.tmp.display()))?
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != MARKER)
            .collect();
        names.sort();
        let first = slam_core::files::read_text(&self.tmp.join(MARKER), &slam_core::files::SMALL).unwrap_or_default();
        let first = first.lines().next().unwrap_or("slam-app");
        write_file(&self.tmp.join(MARKER), format!("{first}\n{}\n", names.join("\n")).as_bytes())?;
        sync_dir(&self.tmp);
        if self.target.exists() {
            if !exchange(&self.tmp, &self.target)? {
                // no atomic swap here: old → backup, new → place, backup removed; a kill between the two
                // renames is repaired by the next run (`create` restores the backup)
                let backup = self.parent.join(format!(".{}.old-{}", self.name, std::process::id()));
                std::fs::rename(&self.target, &backup)
                    .with_context(|| format!("cannot move the old {} aside", self.target.display()))?;
                if let Err(e) = std::fs::rename(&self.tmp, &self.target) {
                    let _ = std::fs::rename(&backup, &self.target);
                    return Err::<(), _>(e)
                        .with_context(|| format!("cannot put the new {} in place", self.target.display()));
                }
                let _ = std::fs::remove_dir_all(&backup);
                self.done = true;
                sync_dir(&self.parent);
                slam_core::files::unregister_temporary(&self.tmp);
                return Ok(());
            }
            // the temporary path now holds the old folder
            if let Err(e) = std::fs::remove_dir_all(&self.tmp) {
                tracing::warn!("the previous output, moved to {}, could not be removed: {e}", self.tmp.display());
            }
        } else {
            std::fs::rename(&self.tmp, &self.target)
                .with_context(|| format!("cannot put {} in place", self.target.display()))?;
        }
        self.done = true;
        sync_dir(&self.parent);
        slam_core::files::unregister_temporary(&self.tmp);
        Ok(())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
        slam_core::files::unregister_temporary(&self.tmp);
    }
}

/// Swap two paths in one step (Linux `renameat2(RENAME_EXCHANGE)`); `Ok(false)` when the file system or
/// the platform cannot.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> Result<bool> {
    use rustix::fs::{renameat_with, RenameFlags, CWD};
    match renameat_with(CWD, a, CWD, b, RenameFlags::EXCHANGE) {
        Ok(()) => Ok(true),
        Err(e)
            if e == rustix::io::Errno::INVAL || e == rustix::io::Errno::NOSYS || e == rustix::io::Errno::OPNOTSUPP =>
        {
            Ok(false)
        }
        Err(e) => Err::<bool, _>(std::io::Error::from(e))
            .with_context(|| format!("cannot put {} in place of {}", a.display(), b.display())),
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_a: &Path, _b: &Path) -> Result<bool> {
    Ok(false)
}

/// Flush a folder's entries to disk (best effort: a crash of the machine, not only of the process).
fn sync_dir(dir: &Path) {
    if let Ok(f) = std::fs::File::open(dir) {
        let _ = f.sync_all();
    }
}

/// Create `dir` and its missing ancestors; returns the folders created, outermost first (so that a
/// command that fails later can take them away again). A component that is a symbolic link which loops
/// or leads nowhere is named as such (the system only says "File exists" or "Too many levels of
/// symbolic links").
pub fn create_folder(dir: &Path) -> std::result::Result<Vec<PathBuf>, String> {
    let mut missing = Vec::new();
    let mut at = Some(dir);
    while let Some(d) = at.filter(|d| !d.as_os_str().is_empty()) {
        match std::fs::symlink_metadata(d) {
            Ok(m) if m.file_type().is_symlink() => {
                if std::fs::metadata(d).is_err() {
                    let to = std::fs::read_link(d).unwrap_or_default();
                    return Err(format!(
                        "{} is a symbolic link to {} that loops or leads nowhere",
                        d.display(),
                        to.display()
                    ));
                }
                break;
            }
            Ok(_) => break,
            Err(_) => missing.push(d.to_path_buf()),
        }
        at = d.parent();
    }
    missing.reverse();
    for d in &missing {
        match std::fs::create_dir(d) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && d.is_dir() => {}
            Err(e) => {
                remove_created(&missing);
                return Err(format!("cannot create {}: {e}", d.display()));
            }
        }
    }
    Ok(missing)
}

/// Remove folders [`create_folder`] made (innermost first), those that are still empty.
pub fn remove_created(folders: &[PathBuf]) {
    for d in folders.iter().rev() {
        let _ = std::fs::remove_dir(d);
    }
}

/// Refuse a destination that is a folder or has no file name; create its parent folder (returning the
/// folders created).
fn prepare_file(path: &Path) -> Result<Vec<PathBuf>> {
    if path.file_name().is_none() || path.is_dir() {
        bail!("{}: is a folder, expected a file name", path.display());
    }
    match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(p) => create_folder(p)
            .map_err(|e| OutputError::Refused(format!("cannot create the folder of {}: {e}", path.display()))),
        None => Ok(Vec::new()),
    }
}

/// Write a whole file atomically ([`slam_core::files::write_atomic`]: a temporary file beside it, synced,
/// renamed over it; removed on failure), creating its folder.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    AtomicFile::new(path)?.write_with(|tmp| std::fs::write(tmp, bytes))
}

/// A file written by someone else's writer (a library function taking a path) and put in place
/// atomically ([`slam_core::files::AtomicWrite`]); dropped unfinished, its temporary file is removed, and
/// so are the folders it created for it.
pub struct AtomicFile {
    write: Option<slam_core::files::AtomicWrite>,
    created: Vec<PathBuf>,
}

impl AtomicFile {
    /// Check `path` can be written (its folder exists or is created, and a file can be made in it) before
    /// any work starts.
    pub fn new(path: &Path) -> Result<Self> {
        let created = prepare_file(path)?;
        match slam_core::files::AtomicWrite::create(path) {
            Ok(w) => Ok(Self { write: Some(w), created }),
            Err(e) => {
                remove_created(&created);
                Err(OutputError::Refused(e.to_string()))
            }
        }
    }

    /// Let `write` write the temporary file, then rename it over the destination.
    pub fn write_with<E: Into<Box<dyn std::error::Error + Send + Sync>>>(
        mut self,
        write: impl FnOnce(&Path) -> std::result::Result<(), E>,
    ) -> Result<()> {
        let Some(w) = self.write.take() else { bail!("the file was already written") };
        let context = || format!("cannot write {}", w.destination().display());
        write(w.temporary()).map_err(|e| OutputError::Writer { context: context(), source: e.into() })?;
        w.commit().map_err(|e| OutputError::Refused(e.to_string()))?;
        self.created.clear();
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        // the temporary file goes first (its own drop), then the folders made for it, if still empty
        drop(self.write.take());
        remove_created(&self.created);
    }
}

/// A path a command writes.
#[derive(Debug, Clone, Copy)]
pub enum Written<'a> {
    /// A file, replaced whole; named by its option (`--ply`) or in words.
    File(&'a str, &'a Path),
    /// A folder, replaced as a whole ([`OutputDir`]).
    Folder(&'a str, &'a Path),
}

/// Where a path leads, resolved one component at a time from the start: symbolic links are followed
/// (a dangling link leads where it points: writing it creates the target), `.` is dropped and `..` takes
/// off the last component. Existing components are canonical, so taking one off is the real parent;
/// components that do not exist yet are no links, so `..` after them is lexical. `DIR/nx/../f` with no
/// `nx` is thus `DIR/f`, the file the system would write once `nx` is created.
pub fn resolve(path: &Path) -> PathBuf {
    let mut out = if path.is_absolute() {
        PathBuf::new()
    } else {
        std::env::current_dir().ok().and_then(|d| std::fs::canonicalize(d).ok()).unwrap_or_default()
    };
    let mut links = 0;
    follow(&mut out, path, &mut links);
    out
}

/// Append `path`'s components to the resolved `out` (see [`resolve`]); `links` counts the symbolic links
/// followed, to stop at a loop (40, as Linux does).
fn follow(out: &mut PathBuf, path: &Path, links: &mut usize) {
    use std::path::Component;
    for c in path.components() {
        match c {
            Component::Prefix(_) | Component::RootDir => *out = PathBuf::from(c.as_os_str()),
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            Component::Normal(n) => {
                let next = out.join(n);
                match std::fs::symlink_metadata(&next) {
                    Ok(m) if m.file_type().is_symlink() && *links < 40 => {
                        *links += 1;
                        match std::fs::read_link(&next) {
                            Ok(to) => follow(out, &to, links),
                            Err(_) => *out = next,
                        }
                    }
                    _ => *out = next,
                }
            }
        }
    }
}

/// Whether two existing paths are one file (hard links included).
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    resolve(a) == resolve(b)
}

/// Refuse a file (`option` at `file`) that lies inside a folder an output replaces as a whole when it
/// ends (`folder_option` at `folder`): it would be lost with the old folder.
pub fn refuse_inside_replaced(option: &str, file: &Path, folder_option: &str, folder: &Path) -> Result<()> {
    if resolve(file).starts_with(resolve(folder)) {
        return Err(OutputError::Refused(format!(
            "{option} {} lies inside {folder_option} {}, which the run replaces as a whole when it ends: give a path outside it",
            file.display(),
            folder.display()
        )));
    }
    Ok(())
}

/// Refuse, before anything is read, an output that is (or resolves to, through symbolic links, `.`,
/// `..` or a hard link) one of the command's inputs, an output folder that holds an input (it is
/// replaced as a whole), and two outputs that are one file. `inputs` are `(what, path)` pairs, files or
/// folders.
pub fn refuse_overwriting_inputs(inputs: &[(&str, &Path)], outputs: &[Written<'_>]) -> Result<()> {
    let resolved: Vec<(&str, &Path, PathBuf)> = inputs.iter().map(|&(w, p)| (w, p, resolve(p))).collect();
    let same = |a: &Path, ra: &Path, b: &Path, rb: &Path| ra == rb || same_file(a, b);
    let shown = |p: &Path, r: &Path| {
        if p == r {
            p.display().to_string()
        } else {
            format!("{} (which is {})", p.display(), r.display())
        }
    };
    let mut files: Vec<(&str, &Path, PathBuf)> = Vec::new();
    let mut folders: Vec<(&str, &Path, PathBuf)> = Vec::new();
    for o in outputs {
        match *o {
            Written::File(option, path) => {
                let r = resolve(path);
                if let Some((what, p, _)) = resolved.iter().find(|(_, p, rp)| same(path, &r, p, rp)) {
                    bail!(
                        "{option} {}: is {what} {}, an input of this command: writing it would replace what is being read; choose another file",
                        shown(path, &r),
                        p.display()
                    );
                }
                // a file already inside an input folder (a dataset's calib.txt next to its images) is
                // the dataset's, even when this command does not read it
                if let Some((what, p, _)) =
                    resolved.iter().find(|(_, p, rp)| p.is_dir() && r.starts_with(rp) && r.exists())
                {
                    bail!(
                        "{option} {}: is a file inside {what} {}, an input of this command: writing it would replace part of that folder; choose a file outside it",
                        shown(path, &r),
                        p.display()
                    );
                }
                if let Some((other, _, _)) = files.iter().find(|(_, p, rp)| same(path, &r, p, rp)) {
                    bail!(
                        "{option} {}: is also the file of {other}: each output needs a file of its own",
                        shown(path, &r)
                    );
                }
                files.push((option, path, r));
            }
            // a path without a name of its own (`.`, `/`) is refused by the folder's own checks
            Written::Folder(_, dir)
                if !matches!(dir.components().next_back(), Some(std::path::Component::Normal(_))) => {}
            Written::Folder(option, dir) => {
                let r = resolve(dir);
                if let Some((what, p, _)) =
                    resolved.iter().find(|(_, p, rp)| rp.starts_with(&r) || same(dir, &r, p, rp))
                {
                    bail!(
                        "{option} {}: holds {what} {}, an input of this command: the folder is replaced as a whole; choose another folder",
                        shown(dir, &r),
                        p.display()
                    );
                }
                folders.push((option, dir, r));
            }
        }
    }
    // a file written into a folder that is itself replaced as a whole would be lost with it (and its
    // temporary file would count as a foreign entry of the folder)
    for (option, path, r) in &files {
        if let Some((folder_option, dir, rd)) = folders.iter().find(|(_, _, rd)| r.starts_with(rd)) {
            bail!(
                "{option} {}: lies inside {folder_option} {}, a folder this command replaces as a whole; choose a file outside it",
                shown(path, r),
                shown(dir, rd)
            );
        }
    }
    Ok(())
}

/// Add `name` (a file written into `dir` after the fact, e.g. `eval`'s `objects_score.json` in a run's
/// folder) to the folder's marker, so that the command that owns the folder may replace it later; a
/// folder without a marker is left as it is.
pub fn record_in_marker(dir: &Path, name: &str) -> Result<()> {
    let marker = dir.join(MARKER);
    let Ok(text) = slam_core::files::read_text(&marker, &slam_core::files::SMALL) else { return Ok(()) };
    let mut lines: Vec<&str> = text.lines().collect();
    if lines.iter().skip(1).any(|l| *l == name) {
        return Ok(());
    }
    let first = lines.first().copied().unwrap_or("slam-app").to_string();
    let mut names: Vec<&str> = lines.drain(..).skip(1).chain([name]).collect();
    names.sort();
    write_file(&marker, format!("{first}\n{}\n", names.join("\n")).as_bytes())
}

/// The names `dir`'s marker lists, and whether it has one.
fn marked_names(dir: &Path) -> (bool, Vec<String>) {
    let marker = dir.join(MARKER);
    match slam_core::files::read_text(&marker, &slam_core::files::SMALL) {
        Ok(t) => (true, t.lines().skip(1).map(str::to_string).collect()),
        Err(_) => (false, Vec::new()),
    }
}

/// Files a command writes into a folder it does not replace as a whole (`map --picture DIR`, `eval RUN`'s
/// `objects_score.json`): the folder may hold other files, but a file of the same name is replaced only
/// when this program wrote it (the folder's marker lists it, as a run folder's lists its `map.png`).
/// Checked when made (before any work); each file is written whole (a temporary folder inside `dir`,
/// then renamed into place) and recorded in the marker, created if the folder has none, so that the
/// next command may replace it again.
pub struct FilesInto {
    dir: PathBuf,
    names: Vec<String>,
    command: String,
    created: Vec<PathBuf>,
}

impl FilesInto {
    /// Check that `names` can be written into `dir` (named `option` in messages) by `slam-app
    /// {command}`: `dir` is a folder or can be made one, and no file of those names is there that this
    /// program did not write.
    pub fn new(dir: &Path, names: &[&str], option: &str, command: &str) -> Result<Self> {
        if dir.exists() && !dir.is_dir() {
            bail!("{option} {}: is a file, expected a folder", dir.display());
        }
        // files written into a folder are renamed into place: a name there that is a pipe, a device or a
        // socket is never renamed over (slam_core::files::output_kind)
        for n in names {
            match slam_core::files::output_kind(&dir.join(n)) {
                Ok(slam_core::files::OutputKind::File) => {}
                Ok(slam_core::files::OutputKind::Pipe) => {
                    bail!("{option} {}: {n} is a named pipe, not a regular file; it would be replaced", dir.display())
                }
                Err(e) => bail!("{option} {}: {e}", dir.display()),
            }
        }
        let (marked, listed) = marked_names(dir);
        let foreign: Vec<&str> = names
            .iter()
            .copied()
            .filter(|n| std::fs::symlink_metadata(dir.join(n)).is_ok() && !listed.iter().any(|l| l == n))
            .collect();
        if !foreign.is_empty() {
            let why = if marked {
                format!("its `{MARKER}` file does not list {}", if foreign.len() == 1 { "it" } else { "them" })
            } else {
                format!("the folder has no `{MARKER}` file")
            };
            bail!(
                "{option} {}: holds {} that `slam-app {command}` did not write ({why}): it would be replaced; choose \
                 another folder or move {} away",
                dir.display(),
                foreign.join(", "),
                if foreign.len() == 1 { "it" } else { "them" }
            );
        }
        let created =
            create_folder(dir).map_err(|e| OutputError::Refused(format!("{option} {}: {e}", dir.display())))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            names: names.iter().map(|n| n.to_string()).collect(),
            command: command.to_string(),
            created,
        })
    }

    /// `write` fills a temporary folder with the files; each is renamed into place and recorded in the
    /// marker. A file `write` makes that was not named when checked is an error (it was not checked).
    /// Returns the final paths.
    pub fn write_with<E: Into<Box<dyn std::error::Error + Send + Sync>>>(
        mut self,
        write: impl FnOnce(&Path) -> std::result::Result<(), E>,
    ) -> Result<Vec<PathBuf>> {
        let tmp = self.dir.join(format!(".partial-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        slam_core::files::register_temporary(&tmp);
        struct Cleanup(PathBuf);
        impl Drop for Cleanup {
            fn drop(&mut self) {
                let _ = std::fs::remove_dir_all(&self.0);
                slam_core::files::unregister_temporary(&self.0);
            }
        }
        let _cleanup = Cleanup(tmp.clone());
        std::fs::create_dir(&tmp).with_context(|| format!("cannot write in {}", self.dir.display()))?;
        write(&tmp).map_err(|e| OutputError::Callback(e.into()))?;
        let mut made: Vec<PathBuf> = std::fs::read_dir(&tmp)
            .with_context(|| format!("cannot list {}", tmp.display()))?
            .flatten()
            .map(|e| e.path())
            .collect();
        made.sort();
        let name_of = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if let Some(p) = made.iter().find(|p| !self.names.contains(&name_of(p))) {
            bail!("{}: {} was written but not checked beforehand", self.dir.display(), name_of(p));
        }
        let mut out = Vec::new();
        for p in made {
            let to = self.dir.join(name_of(&p));
            std::fs::rename(&p, &to).with_context(|| format!("cannot write {}", to.display()))?;
            out.push(to);
        }
        self.created.clear();
        let (marked, _) = marked_names(&self.dir);
        if !marked {
            write_file(&self.dir.join(MARKER), format!("slam-app {}\n", self.command).as_bytes())?;
        }
        for n in &self.names {
            record_in_marker(&self.dir, n)?;
        }
        Ok(out)
    }
}

impl Drop for FilesInto {
    fn drop(&mut self) {
        remove_created(&self.created);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("slam-app-output-{name}-{}", std::process::id()));
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

    #[test]
    fn a_committed_folder_replaces_the_old_one_whole() {
        let root = scratch("commit");
        let dir = root.join("out");
        let o = OutputDir::create(&dir, "--out", "test").expect("new");
        std::fs::write(o.path().join("a.txt"), "1").expect("write");
        std::fs::write(o.path().join("b.txt"), "1").expect("write");
        assert!(!dir.exists(), "nothing in place before the commit");
        o.commit().expect("commit");
        assert_eq!(listing(&dir), [MARKER, "a.txt", "b.txt"]);
        // second run writes only a.txt: b.txt of the first run must not survive
        let o = OutputDir::create(&dir, "--out", "test").expect("again");
        std::fs::write(o.path().join("a.txt"), "2").expect("write");
        assert_eq!(std::fs::read_to_string(dir.join("a.txt")).expect("old"), "1", "old intact while writing");
        o.commit().expect("commit");
        assert_eq!(listing(&dir), [MARKER, "a.txt"]);
        assert_eq!(std::fs::read_to_string(dir.join("a.txt")).expect("new"), "2");
        assert_eq!(listing(&root), ["out"], "no temporary or backup folder left");
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn an_abandoned_folder_leaves_the_old_one_and_no_temporary() {
        let root = scratch("drop");
        let dir = root.join("out");
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(dir.join("a.txt"), "old").expect("write");
        std::fs::write(dir.join(MARKER), "slam-app test\na.txt\n").expect("marker");
        {
            let o = OutputDir::create(&dir, "--out", "test").expect("create");
            std::fs::write(o.path().join("a.txt"), "new").expect("write");
        }
        assert_eq!(std::fs::read_to_string(dir.join("a.txt")).expect("old"), "old");
        assert_eq!(listing(&root), ["out"]);
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn foreign_files_files_and_nameless_paths_are_refused() {
        let root = scratch("foreign");
        let dir = root.join("out");
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(dir.join("a.txt"), "x").expect("write");
        std::fs::write(dir.join("thesis.tex"), "x").expect("write");
        let e = OutputDir::create(&dir, "--out", "test").err().expect("refused").to_string();
        assert!(e.contains("thesis.tex") && e.contains("a.txt") && e.contains(MARKER), "{e}");
        assert_eq!(listing(&root), ["out"], "nothing created when refused");
        // without the marker, even a name the command writes is the user's (their own map.json)
        std::fs::remove_file(dir.join("thesis.tex")).expect("rm");
        let e = OutputDir::create(&dir, "--out", "test").err().expect("refused").to_string();
        assert!(e.contains("(a.txt)") && e.contains("did not write it"), "{e}");
        // a marker lists what the earlier run wrote: other names are foreign
        std::fs::write(dir.join(MARKER), "slam-app test\nb.txt\n").expect("marker");
        let e = OutputDir::create(&dir, "--out", "test").err().expect("refused").to_string();
        assert!(e.contains("(a.txt)"), "{e}");
        #[cfg(unix)]
        {
            let link = root.join("link");
            std::os::unix::fs::symlink(&dir, &link).expect("symlink");
            let e = OutputDir::create(&link, "--out", "test").err().expect("refused").to_string();
            assert!(e.contains("symbolic link"), "{e}");
            std::fs::remove_file(&link).expect("rm");
        }
        let file = root.join("file");
        std::fs::write(&file, "x").expect("write");
        let e = OutputDir::create(&file, "--out", "test").err().expect("refused").to_string();
        assert!(e.contains("is a file"), "{e}");
        for p in [".", "..", "/"] {
            let e = OutputDir::create(Path::new(p), "--out", "test").err().expect("refused").to_string();
            assert!(e.contains("name a folder of its own"), "{p}: {e}");
        }
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn leftovers_of_killed_runs_are_cleaned_and_a_cut_swap_is_restored() {
        let root = scratch("recover");
        let dir = root.join("out");
        // a temporary folder of a dead process (pid far above the kernel's limit) and a backup whose swap
        // was cut after the old folder was moved aside
        std::fs::create_dir_all(root.join(".out.partial-999999999")).expect("tmp");
        std::fs::create_dir_all(root.join(".out.old-999999999")).expect("backup");
        std::fs::write(root.join(".out.old-999999999/a.txt"), "old").expect("write");
        std::fs::write(root.join(".out.old-999999999").join(MARKER), "slam-app test\na.txt\n").expect("marker");
        let o = OutputDir::create(&dir, "--out", "test").expect("create");
        assert_eq!(std::fs::read_to_string(dir.join("a.txt")).expect("restored"), "old");
        drop(o);
        assert_eq!(listing(&root), ["out"]);
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn an_output_that_is_an_input_is_refused_however_it_is_spelled() {
        let root = scratch("inputs");
        let run = root.join("run");
        std::fs::create_dir_all(&run).expect("dir");
        let map = run.join("map.json");
        std::fs::write(&map, "{}").expect("write");
        let inputs = [("the map", map.as_path())];
        let refused = |out: &Path| {
            refuse_overwriting_inputs(&inputs, &[Written::File("--ply", out)]).err().map(|e| e.to_string())
        };
        // the same file, through ./ and ../, through a symbolic link, through a hard link
        let dotted = run.join(".").join("..").join("run").join("map.json");
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&map, root.join("link.json")).expect("symlink");
            std::fs::hard_link(&map, root.join("hard.json")).expect("hard link");
        }
        // through a folder that does not exist yet (`nx/..` is `run` once `nx` is created)
        let through_new = run.join("nx").join("..").join("map.json");
        let deeper = run.join("nx").join("ny").join("..").join("..").join("map.json");
        for out in [map.clone(), dotted, root.join("link.json"), root.join("hard.json"), through_new, deeper] {
            let e = refused(&out).unwrap_or_else(|| panic!("{} accepted", out.display()));
            assert!(e.contains("is the map") && e.contains("an input of this command"), "{e}");
        }
        // a link to a file not yet written that is an input? no: a new file beside the input is fine
        assert_eq!(refused(&run.join("points.ply")), None);
        assert_eq!(refused(&run.join("new/../points.ply")), None);
        assert!(!run.join("nx").exists() && !run.join("new").exists(), "the check creates no folder");
        let e = refuse_overwriting_inputs(
            &[("the images", run.as_path())],
            &[Written::Folder("--overlays", &run.join("nx/../../run"))],
        )
        .expect_err("is the input folder")
        .to_string();
        assert!(e.contains("holds the images"), "{e}");
        // a folder replaced as a whole must not hold an input, nor be one
        let e = refuse_overwriting_inputs(&inputs, &[Written::Folder("--out", &run)]).expect_err("holds").to_string();
        assert!(e.contains("--out") && e.contains("holds the map"), "{e}");
        let e = refuse_overwriting_inputs(&[("the sequence", root.as_path())], &[Written::Folder("--out", &root)])
            .expect_err("is")
            .to_string();
        assert!(e.contains("holds the sequence"), "{e}");
        refuse_overwriting_inputs(&[("the sequence", run.as_path())], &[Written::Folder("--out", &run.join("out"))])
            .expect("an output folder inside an input folder replaces nothing of it");
        // two outputs into one file
        let (a, b) = (run.join("x.ply"), run.join("./x.ply"));
        let e = refuse_overwriting_inputs(&inputs, &[Written::File("--ply", &a), Written::File("--scene", &b)])
            .expect_err("twice")
            .to_string();
        assert!(e.contains("--scene") && e.contains("also the file of --ply"), "{e}");
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn a_file_written_later_into_a_marked_folder_joins_its_marker() {
        let root = scratch("marker");
        let dir = root.join("out");
        let o = OutputDir::create(&dir, "--out", "test").expect("new");
        std::fs::write(o.path().join("a.txt"), "1").expect("write");
        o.commit().expect("commit");
        std::fs::write(dir.join("b.txt"), "added later").expect("write");
        // b.txt is not in the marker: the folder is not ours to replace
        assert!(OutputDir::create(&dir, "--out", "test").is_err());
        record_in_marker(&dir, "b.txt").expect("record");
        record_in_marker(&dir, "b.txt").expect("twice is once");
        let marker = std::fs::read_to_string(dir.join(MARKER)).expect("marker");
        assert_eq!(marker, "slam-app test\na.txt\nb.txt\n");
        drop(OutputDir::create(&dir, "--out", "test").expect("ours again"));
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn atomic_files_replace_whole_and_refuse_folders() {
        let root = scratch("file");
        let f = root.join("sub/x.json");
        write_file(&f, b"one").expect("write");
        write_file(&f, b"two").expect("write");
        assert_eq!(std::fs::read_to_string(&f).expect("read"), "two");
        assert_eq!(listing(&root.join("sub")), ["x.json"]);
        let e = write_file(&root, b"x").expect_err("folder").to_string();
        assert!(e.contains("is a folder"), "{e}");
        // a writer that fails leaves the old file and no temporary
        let e = AtomicFile::new(&f)
            .expect("new")
            .write_with(|_| Err(std::io::Error::other("encoder broke")))
            .expect_err("fails");
        assert!(e.to_string().contains("encoder broke"), "{e}");
        assert_eq!(std::fs::read_to_string(&f).expect("read"), "two");
        assert_eq!(listing(&root.join("sub")), ["x.json"]);
        let into = FilesInto::new(&root.join("sub"), &["p.svg"], "--picture", "map").expect("into");
        let files = into.write_with(|t| std::fs::write(t.join("p.svg"), "s")).expect("into");
        assert_eq!(files, [root.join("sub/p.svg")]);
        assert_eq!(listing(&root.join("sub")), [MARKER, "p.svg", "x.json"]);
        // written again: the marker lists it; a user's file of that name elsewhere is refused
        FilesInto::new(&root.join("sub"), &["p.svg"], "--picture", "map").expect("ours to replace");
        std::fs::write(root.join("mine.svg"), "mine").expect("write");
        let e = FilesInto::new(&root, &["mine.svg"], "--picture", "map").err().expect("not ours").to_string();
        assert!(e.contains("holds mine.svg that `slam-app map` did not write"), "{e}");
        std::fs::remove_dir_all(&root).ok();
    }
}
