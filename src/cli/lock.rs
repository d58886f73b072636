//! Locks on the places a run writes, so that two runs never write into one place at
//! once: a replay, eval or compare into one `--out` (the folder would mix two runs, and
//! each would clear the other's frames), and a batch item's folder (two runs of one
//! shard, such as a resubmitted job array, would clear each other's items).
//!
//! A lock is `flock(2)` on a hidden file holding the holder's process id and command
//! line: `.relume.lock` in an output folder, `.ID.lock` beside batch item `ID`'s folder.
//! The kernel releases it when the holder exits, however it exits (a crash or SIGKILL
//! included): no lock outlives its process. An item's lock file is removed when the
//! item ends, so a finished batch folder holds only its items; a taker checks that the
//! file it locked is still the one at the path, so removal cannot let two runs in.

use anyhow::{Context, bail};
use std::fs::File;
use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

/// A lock held until dropped (or the process ends).
pub struct Lock {
    _file: File,
}

/// A batch item's lock: held until dropped, when its file is removed.
pub struct ItemLock {
    path: PathBuf,
    _lock: Lock,
}

impl Drop for ItemLock {
    fn drop(&mut self) {
        // Removed while still held: a run that opened the file before the removal finds,
        // once it has the lock, that the path no longer names its file, and takes again.
        let _ = std::fs::remove_file(&self.path);
    }
}

/// The lock file of batch item `id` in batch folder `out`.
pub fn item_lock_path(out: &Path, id: &str) -> PathBuf {
    out.join(format!(".{id}.lock"))
}

/// Takes the lock of batch item `id` in `out`, or gives the description of the process
/// that holds it ("pid 123: relume batch ...").
pub fn lock_item(out: &Path, id: &str) -> anyhow::Result<Result<ItemLock, String>> {
    let path = item_lock_path(out, id);
    Ok(take(&path)?.map(|lock| ItemLock { path, _lock: lock }))
}

/// The lock file of output folder `dir`.
pub fn output_lock_path(dir: &Path) -> PathBuf {
    dir.join(".relume.lock")
}

/// Takes the lock of output folder `dir` (created if missing), or fails naming the
/// process that holds it.
pub fn lock_output(dir: &Path, option: &str) -> anyhow::Result<Lock> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let path = output_lock_path(dir);
    match take(&path)? {
        Ok(lock) => Ok(lock),
        Err(holder) => bail!(
            "{option} {} is in use by another relume run ({holder}): wait for it to finish, \
             or give another {option}",
            dir.display()
        ),
    }
}

/// The lock at `path`, or (when another process holds it) that process's
/// description: "pid 123: relume replay ...".
fn take(path: &Path) -> anyhow::Result<Result<Lock, String>> {
    // A file removed (by its holder, as it let go) between our open and our lock is
    // locked in vain: take the new one. Two tries are rare; a few are plenty.
    for _ in 0..8 {
        match take_once(path)? {
            Taken::Locked(file) if still_at(&file, path) => return Ok(Ok(Lock { _file: file })),
            Taken::Locked(_) => continue,
            Taken::Held(holder) => return Ok(Err(holder)),
        }
    }
    bail!("cannot lock {}: it keeps being replaced", path.display())
}

enum Taken {
    Locked(File),
    Held(String),
}

/// Whether `path` still names the file `file` has open.
fn still_at(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(open), Ok(named)) => open.dev() == named.dev() && open.ino() == named.ino(),
        _ => false,
    }
}

/// Whether `flock` failed because the file system has no locks, not because of a holder.
fn cannot_lock_here(e: &std::io::Error) -> bool {
    matches!(
        e.raw_os_error(),
        Some(libc::ENOSYS | libc::EOPNOTSUPP | libc::ENOLCK)
    )
}

fn take_once(path: &Path) -> anyhow::Result<Taken> {
    let mut file = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .with_context(|| format!("cannot open the lock file {}", path.display()))?;
    let operation = libc::LOCK_EX | libc::LOCK_NB;
    // SAFETY: flock on a file descriptor this function owns, open for its whole call.
    if unsafe { libc::flock(file.as_raw_fd(), operation) } != 0 {
        let e = std::io::Error::last_os_error();
        if cannot_lock_here(&e) {
            // Lustre without -o flock, some NFS mounts: running unguarded is better
            // than failing every run; said once per process.
            static SAID: std::sync::Once = std::sync::Once::new();
            SAID.call_once(|| {
                eprintln!(
                    "warning: {}: this file system does not take locks ({e}): two relume \
                     runs into one folder would not be kept apart here",
                    path.display()
                )
            });
            return Ok(Taken::Locked(file));
        }
        if e.kind() != std::io::ErrorKind::WouldBlock {
            return Err(e).with_context(|| format!("cannot lock {}", path.display()));
        }
        let mut holder = String::new();
        let _ = file.read_to_string(&mut holder);
        let holder = holder.trim();
        return Ok(Taken::Held(if holder.is_empty() {
            "a process that has not said which yet".to_string()
        } else {
            holder.to_string()
        }));
    }
    let me = format!(
        "pid {}: {}",
        std::process::id(),
        std::env::args().collect::<Vec<_>>().join(" ")
    );
    let written = file
        .set_len(0)
        .and_then(|_| file.rewind())
        .and_then(|_| file.write_all(me.as_bytes()));
    written.with_context(|| format!("cannot write the lock file {}", path.display()))?;
    Ok(Taken::Locked(file))
}

#[cfg(test)]
mod tests {
    use super::cannot_lock_here;
    use std::io::Error;

    #[test]
    fn a_file_system_without_locks_is_told_from_a_held_lock() {
        for errno in [libc::ENOSYS, libc::EOPNOTSUPP, libc::ENOLCK] {
            assert!(
                cannot_lock_here(&Error::from_raw_os_error(errno)),
                "{errno}"
            );
        }
        for errno in [libc::EWOULDBLOCK, libc::EBADF, libc::EINTR] {
            assert!(
                !cannot_lock_here(&Error::from_raw_os_error(errno)),
                "{errno}"
            );
        }
    }
}
