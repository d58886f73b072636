//! Locks on the places a run writes, so that two runs never write into one place at
//! once: a replay, eval or compare into one `--out` (the folder would mix two runs, and
//! each would clear the other's frames).
//!
//! A lock is `flock(2)` on a hidden file (`.relume.lock` in the output folder) holding
//! the holder's process id and command line. The kernel releases it when the holder exits, however it exits (a crash or
//! SIGKILL included): no lock outlives its process, and nothing needs cleaning up.

use anyhow::{Context, bail};
use std::fs::File;
use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

/// A lock held until dropped (or the process ends).
pub struct Lock {
    _file: File,
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
        if e.kind() != std::io::ErrorKind::WouldBlock {
            return Err(e).with_context(|| format!("cannot lock {}", path.display()));
        }
        let mut holder = String::new();
        let _ = file.read_to_string(&mut holder);
        let holder = holder.trim();
        return Ok(Err(if holder.is_empty() {
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
    Ok(Ok(Lock { _file: file }))
}
