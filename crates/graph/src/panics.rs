//! Panics inside a stage: the runtime catches them and reports a clean error naming
//! the stage and frame, so the CLI's panic hook ([`quiet_in_stages`]) keeps Rust's raw
//! panic output (and a backtrace under `RUST_BACKTRACE`) for every other thread and
//! records, for a stage's own thread, where it panicked, which the runtime's error
//! then quotes.

use std::cell::{Cell, RefCell};

thread_local! {
    /// True while the current thread runs a stage's `process` under the runtime's
    /// `catch_unwind`.
    static IN_STAGE: Cell<bool> = const { Cell::new(false) };
    /// Where the current thread's last caught stage panic happened.
    static LOCATION: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Runs `f` as a stage's work: a panic in it (on this thread) is the runtime's to
/// report.
pub(super) fn in_stage<T>(f: impl FnOnce() -> T) -> T {
    IN_STAGE.with(|s| s.set(true));
    LOCATION.with(|l| l.borrow_mut().take());
    let out = f();
    IN_STAGE.with(|s| s.set(false));
    out
}

/// Where the current thread's stage panicked (`file:line:column`), once.
fn take_location() -> Option<String> {
    LOCATION.with(|l| l.borrow_mut().take())
}

/// A caught panic's message, with where the stage panicked when the hook recorded it
/// (see [`quiet_in_stages`]).
pub(super) fn panic_message(panic: Box<dyn std::any::Any + Send>) -> String {
    let message = if let Some(s) = panic.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = panic.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic payload".into()
    };
    match take_location() {
        Some(at) => format!("{message} (at {at})"),
        None => message,
    }
}

/// Installs a panic hook that stays quiet for panics the runtime catches in a stage's
/// thread (it records their location instead) and calls the previous hook for all
/// others. For the CLI: a library user keeps their own hook.
pub fn quiet_in_stages() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if IN_STAGE.with(|s| s.get()) {
            let at = info
                .location()
                .map(|l| format!("{}:{}:{}", l.file(), l.line(), l.column()));
            LOCATION.with(|l| *l.borrow_mut() = at);
            return;
        }
        previous(info);
    }));
}
