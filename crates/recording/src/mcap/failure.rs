//! The `mcap` crate's errors, in words.

/// An MCAP error in words, with the cause the crate's own message leaves out: its I/O
/// error says only "I/O error from writing, or reading a compression stream", which
/// would hide "No space left on device".
pub(crate) fn describe(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::Io(io) => format!("{e}: {io}"),
        _ => e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_io_error_keeps_its_cause() {
        let full = std::io::Error::from_raw_os_error(28);
        let e = mcap::McapError::Io(full);
        assert_eq!(
            super::describe(&e),
            "I/O error from writing, or reading a compression stream: No space left on device (os error 28)"
        );
    }
}
