//! What a command prints and where its files go: the closing line of an import, checks
//! on output paths before any work, writing to standard output, and the message of an
//! error that ended a command.

use std::path::{Path, PathBuf};

/// The line that import and export end with: what `out` holds, its size, the time.
pub(crate) fn print_wrote(
    out: &Path,
    (color, depth, poses): (usize, usize, usize),
    extra: &str,
    start: std::time::Instant,
) -> anyhow::Result<()> {
    let bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    outln!(
        "wrote {} ({color} color, {depth} depth, {poses} poses{extra}, {:.1} MB) in {:.2} s",
        out.display(),
        bytes as f64 / 1e6,
        start.elapsed().as_secs_f64()
    )
}

/// An error when the output `out` is the input file `input` (written over before it is
/// read to its end).
pub(crate) fn check_not_input(out: &Path, input: &Path) -> anyhow::Result<()> {
    if let (Ok(a), Ok(b)) = (out.canonicalize(), input.canonicalize())
        && a == b
    {
        anyhow::bail!(
            "-o {} is the input file: give the output another name",
            out.display()
        );
    }
    Ok(())
}

/// An error before any work (a replay, a synth, an import), rather than after it, when
/// the file an option names cannot be written: something other than a regular file
/// stands there (a folder, a device), or its folder does not exist.
pub(crate) fn check_output_file(option: &str, path: &Path) -> anyhow::Result<()> {
    // Where the file will be written: through a symbolic link, to what it leads to.
    let target = relume::recording::writer::output_target(path)
        .map_err(|e| anyhow::anyhow!("{option} {}: {e}", path.display()))?;
    if let Some(folder) = target.parent()
        && !folder.as_os_str().is_empty()
        && !folder.is_dir()
    {
        anyhow::bail!(
            "{option} {}: the folder {} does not exist",
            path.display(),
            folder.display()
        );
    }
    Ok(())
}

/// Writes to standard output: an error naming it when that fails, where `print!`
/// would panic. A reader that went away ([`is_broken_pipe`]) ends the command quietly.
pub fn stdout_write(text: std::fmt::Arguments) -> anyhow::Result<()> {
    use std::io::Write;
    std::io::stdout()
        .lock()
        .write_fmt(text)
        .map_err(|e| anyhow::Error::new(e).context("cannot write to standard output"))
}

/// Whether `error` comes from writing into a pipe whose reader has closed it (as in
/// `relume stages | head`): the output is no longer wanted, so the command ends with
/// status 0 and no message, as ripgrep does.
pub fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// The message for an error that ended a command: its causes from the outermost in,
/// joined by ": ", each said once. The library's errors name their cause in their own
/// message (so that `{}` alone is complete) and also hand it on as their `source`, so
/// the plain chain would repeat it (`a: b: b`); a cause whose text already ends the
/// message is left out.
pub fn report(error: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        // The cause ends the message as its own part (after ": "), not by chance.
        if message == text || message.ends_with(&format!(": {text}")) {
            continue;
        }
        if !message.is_empty() {
            message.push_str(": ");
        }
        message.push_str(&text);
    }
    message
}

/// Where the built-in default recording is kept.
pub(crate) fn default_recording_path() -> PathBuf {
    PathBuf::from("recordings").join("default.relume")
}

#[cfg(test)]
mod tests {
    use super::report;

    #[derive(Debug, thiserror::Error)]
    #[error("{path}: {source}")]
    struct Named {
        path: &'static str,
        #[source]
        source: std::io::Error,
    }

    #[derive(Debug, thiserror::Error)]
    #[error("stage `write` could not be set up: {source}")]
    struct Setup {
        #[source]
        source: Named,
    }

    fn not_a_directory() -> std::io::Error {
        std::io::Error::other("Not a directory")
    }

    #[test]
    fn each_cause_is_said_once() {
        let error = anyhow::Error::new(Setup {
            source: Named {
                path: "/dev/null/x/final",
                source: not_a_directory(),
            },
        })
        .context("replay of r.relume stopped");
        assert_eq!(
            report(&error),
            "replay of r.relume stopped: stage `write` could not be set up: \
             /dev/null/x/final: Not a directory"
        );
    }

    #[test]
    fn causes_not_in_the_message_are_kept() {
        // A context over an error that does not repeat it, and an error whose message
        // does not name its source: every part is said.
        let error = anyhow::Error::new(not_a_directory())
            .context("cannot write out/final/000001.png")
            .context("frame 1");
        assert_eq!(
            report(&error),
            "frame 1: cannot write out/final/000001.png: Not a directory"
        );
    }
}
