//! Atomic output. Every file is written to a temporary file in its destination folder
//! (`.workbench-*.tmp`, which no reader looks at), flushed to disk (`fsync`) and renamed into
//! place, and the folder is synced, so a reader never sees a half-written file and a failed run
//! leaves none behind.
//!
//! A command that writes several files makes them one set ([`OutputSet`]): while the set is open,
//! every file written under its roots stays a temporary; [`OutputSet::commit`] renames them all
//! at the end, in the order written (the file readers trust — `fit.json`, `intrinsics.json`,
//! `detections.json`, the table's sidecar — is written last, so it is renamed last), then syncs
//! their folders. A run that fails or is killed before the commit leaves the previous set as it
//! was (a killed run's temporaries stay behind under their hidden names; nothing reads them). Only
//! the renames themselves, microseconds, can be cut short by a kill: the trusted file is then
//! still the previous one, beside some of the new files.

use crate::error::{Error, Result};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;

/// A file written and synced, waiting for its set's commit.
struct Pending {
    tmp: tempfile::TempPath,
    dest: PathBuf,
}

/// An open set: the folders and files it covers, and what was written under them.
struct Open {
    id: u64,
    roots: Vec<PathBuf>,
    pending: Vec<Pending>,
}

/// The open sets of this process (one per command; several when tests run commands in parallel,
/// each in its own folders).
static OPEN: Mutex<Vec<Open>> = Mutex::new(Vec::new());
static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// Every temporary this process has created and not yet renamed into place: what an interrupted
/// run deletes on its way out ([`exit_discarding_temporaries`]).
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Delete every temporary not yet renamed into place and exit with `code`, for a run stopped by
/// SIGINT or SIGTERM (the binary's signal thread calls it; issue 33: `plot` and `lut` left
/// `.workbench-*.tmp` files). The previous outputs stay as they were: nothing was renamed over
/// them. A file already renamed or deleted is skipped. The list stays locked until the process
/// has gone, so a thread still writing cannot create a temporary after the clean-up: temporaries
/// are created under the same lock ([`write_atomic`]).
pub fn exit_discarding_temporaries(code: i32) -> ! {
    let mut live = live();
    for p in live.drain(..) {
        let _ = std::fs::remove_file(p);
    }
    std::process::exit(code)
}

fn open_sets() -> std::sync::MutexGuard<'static, Vec<Open>> {
    OPEN.lock().unwrap_or_else(|e| e.into_inner())
}

/// `path` made absolute (without touching the file system), for comparing with a set's roots.
fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The outputs of one command, committed together (module doc). Dropped without a commit (an
/// error on the way), its temporaries are deleted and the previous outputs stay.
#[must_use = "an output set is committed with commit(); dropped, its files are discarded"]
pub struct OutputSet {
    id: u64,
}

impl OutputSet {
    /// Open a set covering `roots`: output files, and folders whose files (at any depth) belong
    /// to it. Each root must be missing, a regular file or a folder ([`replaceable`]): a special
    /// file or a link to a file is refused before anything is written.
    pub fn begin(roots: &[&Path]) -> Result<OutputSet> {
        check_roots(roots)?;
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        open_sets().push(Open {
            id,
            roots: roots.iter().map(|r| absolute(r)).collect(),
            pending: vec![],
        });
        Ok(OutputSet { id })
    }

    fn take(&self) -> Option<Open> {
        let mut sets = open_sets();
        let k = sets.iter().position(|o| o.id == self.id)?;
        Some(sets.remove(k))
    }

    /// Rename every file written under the set into place, in the order written, and sync their
    /// folders.
    pub fn commit(self) -> Result<()> {
        let Some(open) = self.take() else {
            return Ok(());
        };
        let mut dirs: Vec<PathBuf> = vec![];
        for p in open.pending {
            let tmp_path = p.tmp.to_path_buf();
            p.tmp
                .persist(&p.dest)
                .map_err(|e| Error::io(&p.dest, e.error))?;
            live().retain(|l| *l != tmp_path);
            let dir = parent(&p.dest).to_path_buf();
            if !dirs.contains(&dir) {
                dirs.push(dir);
            }
        }
        for d in dirs {
            sync_dir(&d)?;
        }
        Ok(())
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        // Not committed: the temporaries go (TempPath deletes its file when dropped).
        drop(self.take());
    }
}

fn parent(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Sync a folder, so that the renames in it survive a power cut (a no-op where folders cannot be
/// opened for that, e.g. on Windows).
fn sync_dir(dir: &Path) -> Result<()> {
    #[cfg(unix)]
    {
        std::fs::File::open(dir)
            .and_then(|f| f.sync_all())
            .map_err(|e| Error::io(dir, e))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// Refuse, before any work, outputs that [`OutputSet::begin`] would refuse at the end: each root
/// missing, a regular file, or a folder (or a link to one).
pub fn check_roots(roots: &[&Path]) -> Result<()> {
    roots.iter().try_for_each(|r| replaceable(r, true))
}

/// Whether an output may go to `path`: nothing there, or a regular file (replaced by the rename),
/// or — where `folder_ok`, for a set's roots — a folder or a link to one (written into). Anything
/// else is refused in one line: the rename would replace a FIFO, a device such as /dev/null or
/// /dev/stdout, or a symbolic link, with a regular file.
fn replaceable(path: &Path, folder_ok: bool) -> Result<()> {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Ok(());
    };
    let kind = meta.file_type();
    if kind.is_file() || (folder_ok && std::fs::metadata(path).is_ok_and(|m| m.is_dir())) {
        return Ok(());
    }
    let what = if kind.is_symlink() {
        "a symbolic link: give the path it points to"
    } else if kind.is_dir() {
        "a folder, where a file is written"
    } else {
        "not a regular file (a device, FIFO or socket): outputs replace only regular files"
    };
    Err(Error::invalid(path, format!("the output path is {what}")))
}

/// Files written so far by this process, for the test hook below.
static WRITTEN: AtomicUsize = AtomicUsize::new(0);

/// Test hooks: with `WORKBENCH_ABORT_AFTER_WRITES=n` in the environment, the process aborts (as
/// if killed) right after its n-th output file is written, before any later rename or commit;
/// with `WORKBENCH_PAUSE_AFTER_WRITES=n` it waits 30 s there instead, for a test to signal it.
/// The kill tests (`tests/it/reliability.rs`) use them to stop commands at every point.
fn abort_hook() {
    let n = WRITTEN.fetch_add(1, Ordering::SeqCst) + 1;
    let at = |var: &str| {
        std::env::var_os(var).and_then(|v| v.to_str().and_then(|v| v.parse::<usize>().ok()))
            == Some(n)
    };
    if at("WORKBENCH_ABORT_AFTER_WRITES") {
        std::process::abort();
    }
    if at("WORKBENCH_PAUSE_AFTER_WRITES") {
        std::thread::sleep(std::time::Duration::from_secs(30));
    }
}

/// Write a file atomically through a writer callback: into its open [`OutputSet`], if one covers
/// it, else into place at once.
pub(crate) fn write_atomic<F>(path: &Path, write: F) -> Result<()>
where
    F: FnOnce(&mut std::io::BufWriter<&mut std::fs::File>) -> std::io::Result<()>,
{
    replaceable(path, false)?;
    let dir = parent(path);
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    // Created and listed under one lock, so that an interrupted run finds every temporary.
    let mut tmp = {
        let mut live = live();
        let tmp = tempfile::Builder::new()
            .prefix(".workbench-")
            .suffix(".tmp")
            .tempfile_in(dir)
            .map_err(|e| Error::io(dir, e))?;
        live.push(tmp.path().to_path_buf());
        tmp
    };
    {
        let mut w = std::io::BufWriter::new(tmp.as_file_mut());
        write(&mut w).map_err(|e| Error::io(path, e))?;
        w.flush().map_err(|e| Error::io(path, e))?;
    }
    // Temporary files are created private (0600); give the result the usual permissions.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let perm = std::fs::Permissions::from_mode(0o644);
        tmp.as_file()
            .set_permissions(perm)
            .map_err(|e| Error::io(path, e))?;
    }
    tmp.as_file().sync_all().map_err(|e| Error::io(path, e))?;
    abort_hook();
    let dest = absolute(path);
    {
        let mut sets = open_sets();
        if let Some(set) = sets
            .iter_mut()
            .find(|o| o.roots.iter().any(|r| dest.starts_with(r)))
        {
            set.pending.push(Pending {
                tmp: tmp.into_temp_path(),
                dest,
            });
            return Ok(());
        }
    }
    let tmp_path = tmp.path().to_path_buf();
    tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
    live().retain(|l| *l != tmp_path);
    sync_dir(dir)
}

/// Write bytes atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// Write pretty JSON atomically, with a trailing newline.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value).map_err(|e| Error::Json {
        path: path.to_path_buf(),
        err: e,
    })?;
    text.push('\n');
    write_bytes(path, text.as_bytes())
}

/// Read and parse a JSON file.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    crate::formats::input::regular_file(path)?;
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| Error::Json {
        path: path.to_path_buf(),
        err: e,
    })
}
