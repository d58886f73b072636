//! The running program of an external stage: started once, spoken to over its standard
//! input and output, its standard error passed on to relume's (each line prefixed with
//! the stage's name) and its last lines kept for error messages. A watchdog stops the
//! program when a request goes unanswered past the stage's timeout, or when the user
//! interrupts the run (`relume_base::cancel`) while the program is busy; dropping a
//! [`Program`] ends it (asked first, then killed).

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::os::unix::process::CommandExt;
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// How many of the program's last standard-error lines an error message shows.
const STDERR_TAIL: usize = 12;

/// How long a program has to exit after the end of the stream (or after its output
/// closed) before it is killed.
const EXIT_GRACE: Duration = Duration::from_secs(5);

pub struct Program {
    /// The command line, for messages.
    pub command_line: String,
    child: Arc<Mutex<Child>>,
    pub stdin: Option<BufWriter<ChildStdin>>,
    pub stdout: BufReader<ChildStdout>,
    stderr_tail: Arc<Mutex<VecDeque<String>>>,
    stderr_done: mpsc::Receiver<()>,
    watchdog: Watchdog,
}

impl Program {
    /// Starts `command` (program and arguments), its standard error lines passed on
    /// prefixed with `[stage]`.
    pub fn start(stage: &str, command: &[String]) -> Result<Program, String> {
        let command_line = command.join(" ");
        let mut child = Command::new(&command[0])
            .args(&command[1..])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            // A group of its own, so that stopping it stops what it started too (a shell
            // wrapper that runs python without `exec`). An interrupt reaches it through
            // the watchdog and `Drop` instead of the terminal.
            .process_group(0)
            .spawn()
            .map_err(|e| {
                let hint = match e.kind() {
                    std::io::ErrorKind::NotFound => {
                        " (no such program: is it installed, or the path right?)"
                    }
                    std::io::ErrorKind::PermissionDenied => {
                        " (not executable: `chmod +x` it, or name its `interpreter`)"
                    }
                    _ => "",
                };
                format!("cannot start `{command_line}`: {e}{hint}")
            })?;
        let stdin = child
            .stdin
            .take()
            .map(|s| BufWriter::with_capacity(1 << 16, s));
        let stdout = BufReader::with_capacity(1 << 16, child.stdout.take().expect("piped"));
        let stderr = child.stderr.take().expect("piped");
        let stderr_tail = Arc::new(Mutex::new(VecDeque::new()));
        let (done_tx, stderr_done) = mpsc::channel();
        let tail = stderr_tail.clone();
        let prefix = format!("[{stage}] ");
        let spawned = std::thread::Builder::new()
            .name(format!("{stage} stderr"))
            .spawn(move || {
                for line in BufReader::new(stderr).lines() {
                    let Ok(line) = line else { break };
                    // Not eprintln!: with relume's stderr closed it would panic this
                    // thread, and the program would block on a full stderr pipe.
                    let _ = writeln!(std::io::stderr(), "{prefix}{line}");
                    let mut tail = tail.lock().unwrap_or_else(|e| e.into_inner());
                    if tail.len() == STDERR_TAIL {
                        tail.pop_front();
                    }
                    tail.push_back(line);
                }
                let _ = done_tx.send(());
            });
        let child = Arc::new(Mutex::new(child));
        if let Err(e) = spawned {
            kill(&child);
            return Err(format!(
                "cannot start a thread to read `{command_line}`: {e}"
            ));
        }
        let watchdog = Watchdog::start(stage, child.clone()).inspect_err(|_| kill(&child))?;
        Ok(Program {
            command_line,
            child,
            stdin,
            stdout,
            stderr_tail,
            stderr_done,
            watchdog,
        })
    }

    /// Runs `exchange` (a request and its reply) with the program stopped if it takes
    /// longer than `timeout` or the run is interrupted; `Err` says which stopped it.
    pub fn within<T>(
        &mut self,
        timeout: Duration,
        exchange: impl FnOnce(&mut Program) -> T,
    ) -> Result<T, Stopped> {
        self.watchdog.arm(Instant::now() + timeout);
        let out = exchange(self);
        match self.watchdog.disarm() {
            Some(why) => Err(why),
            None => Ok(out),
        }
    }

    /// Why the program stopped talking: its exit status (waited for a moment) and its
    /// last lines of standard error.
    pub fn death(&mut self) -> String {
        let status = self.wait_for_exit(EXIT_GRACE);
        // The last lines may still be on their way.
        let _ = self.stderr_done.recv_timeout(Duration::from_millis(500));
        let exit = match status {
            Some(status) => describe(status),
            None => "is still running but stopped reading or writing the protocol".to_string(),
        };
        format!("the program {exit}{}", self.stderr_tail())
    }

    /// The program's last lines of standard error, as the end of a message.
    pub fn stderr_tail(&self) -> String {
        let tail = self.stderr_tail.lock().unwrap_or_else(|e| e.into_inner());
        if tail.is_empty() {
            return "; it wrote nothing to standard error".to_string();
        }
        let lines: Vec<&str> = tail.iter().map(String::as_str).collect();
        format!(
            "; its last lines of standard error:\n  {}",
            lines.join("\n  ")
        )
    }

    /// Closes the program's input and waits for it to exit (killing it after a grace
    /// period); the status, or `None` when it had to be killed.
    pub fn finish(&mut self) -> Option<ExitStatus> {
        self.stdin = None;
        let status = self.wait_for_exit(EXIT_GRACE);
        if status.is_none() {
            kill(&self.child);
        }
        status
    }

    fn wait_for_exit(&self, grace: Duration) -> Option<ExitStatus> {
        let end = Instant::now() + grace;
        loop {
            let status = self
                .child
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .try_wait();
            match status {
                Ok(Some(status)) => return Some(status),
                Ok(None) if Instant::now() < end => std::thread::sleep(Duration::from_millis(5)),
                _ => return None,
            }
        }
    }
}

impl Drop for Program {
    fn drop(&mut self) {
        self.stdin = None;
        let _ = self.wait_for_exit(Duration::from_millis(200));
        // Whatever it started and left behind goes with it.
        kill(&self.child);
    }
}

/// An exit status in words: "exited with status 3", "was killed by signal 9".
pub fn describe(status: ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exited with status {code}"),
        (None, Some(signal)) => format!("was killed by signal {signal}"),
        _ => format!("ended ({status})"),
    }
}

/// Kills the program and every process of its group, then reaps it.
fn kill(child: &Mutex<Child>) {
    let mut child = child.lock().unwrap_or_else(|e| e.into_inner());
    if let Ok(pid) = i32::try_from(child.id()) {
        // SAFETY: kill(2) with the program's own process group (its pid, as
        // `process_group(0)` made it); a group already gone gives ESRCH, ignored.
        unsafe {
            libc::kill(-pid, libc::SIGKILL);
        }
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Why the watchdog stopped the program.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stopped {
    /// It did not answer in time.
    TimedOut,
    /// The user interrupted the run while it worked.
    Interrupted,
}

/// How often an armed watchdog looks for an interrupt.
const INTERRUPT_POLL: Duration = Duration::from_millis(50);

/// A thread that kills the program when an armed deadline passes.
struct Watchdog {
    state: Arc<(Mutex<WatchState>, Condvar)>,
    thread: Option<std::thread::JoinHandle<()>>,
}

#[derive(Default)]
struct WatchState {
    deadline: Option<Instant>,
    fired: Option<Stopped>,
    quit: bool,
}

impl Watchdog {
    fn start(stage: &str, child: Arc<Mutex<Child>>) -> Result<Watchdog, String> {
        let state = Arc::new((Mutex::new(WatchState::default()), Condvar::new()));
        let shared = state.clone();
        let thread = std::thread::Builder::new()
            .name(format!("{stage} watchdog"))
            .spawn(move || {
                let (lock, wake) = &*shared;
                let mut s = lock.lock().unwrap_or_else(|e| e.into_inner());
                while !s.quit {
                    match s.deadline {
                        None => s = wake.wait(s).unwrap_or_else(|e| e.into_inner()),
                        Some(deadline) => {
                            let now = Instant::now();
                            let why = if relume_base::cancel::requested() {
                                Some(Stopped::Interrupted)
                            } else if now >= deadline {
                                Some(Stopped::TimedOut)
                            } else {
                                None
                            };
                            if let Some(why) = why {
                                s.deadline = None;
                                s.fired = Some(why);
                                kill(&child);
                            } else {
                                s = wake
                                    .wait_timeout(s, (deadline - now).min(INTERRUPT_POLL))
                                    .unwrap_or_else(|e| e.into_inner())
                                    .0;
                            }
                        }
                    }
                }
            })
            .map_err(|e| format!("cannot start the stage's watchdog thread: {e}"))?;
        Ok(Watchdog {
            state,
            thread: Some(thread),
        })
    }

    fn arm(&self, deadline: Instant) {
        let (lock, wake) = &*self.state;
        let mut s = lock.lock().unwrap_or_else(|e| e.into_inner());
        s.deadline = Some(deadline);
        s.fired = None;
        wake.notify_one();
    }

    /// Disarms; why the program was stopped, if it was.
    fn disarm(&self) -> Option<Stopped> {
        let (lock, wake) = &*self.state;
        let mut s = lock.lock().unwrap_or_else(|e| e.into_inner());
        s.deadline = None;
        wake.notify_one();
        std::mem::take(&mut s.fired)
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        {
            let (lock, wake) = &*self.state;
            lock.lock().unwrap_or_else(|e| e.into_inner()).quit = true;
            wake.notify_one();
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
