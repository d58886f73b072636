//! Reading the files a user names (pipelines, meshes, environment maps, imported
//! images and lists): only regular files, so that a device such as `/dev/zero` or a
//! named pipe gives an error instead of reading without end or waiting forever.

use std::io::{Error, ErrorKind};
use std::path::Path;

/// The bytes of the regular file at `path` (links followed); an error of kind
/// `InvalidInput` for a folder, device, pipe or socket.
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    check_regular(path)?;
    std::fs::read(path)
}

/// [`read_regular`] as UTF-8 text.
pub fn read_regular_to_string(path: &Path) -> std::io::Result<String> {
    check_regular(path)?;
    std::fs::read_to_string(path).map_err(|e| match e.kind() {
        // std says "stream did not contain valid UTF-8", which does not say what is wrong.
        ErrorKind::InvalidData => Error::new(
            ErrorKind::InvalidData,
            "is not a text file (not valid UTF-8)",
        ),
        _ => e,
    })
}

/// The regular file at `path` opened for reading (for files streamed, not read whole).
pub fn open_regular(path: &Path) -> std::io::Result<std::fs::File> {
    check_regular(path)?;
    std::fs::File::open(path)
}

fn check_regular(path: &Path) -> std::io::Result<()> {
    let kind = std::fs::metadata(path)?.file_type();
    if kind.is_file() {
        return Ok(());
    }
    let what = if kind.is_dir() {
        "a folder"
    } else {
        "not a regular file (a device, pipe or socket)"
    };
    Err(Error::new(ErrorKind::InvalidInput, format!("is {what}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_are_read_and_others_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a.txt");
        std::fs::write(&file, "text").unwrap();
        assert_eq!(read_regular(&file).unwrap(), b"text");
        assert_eq!(read_regular_to_string(&file).unwrap(), "text");
        let e = read_regular(dir.path()).unwrap_err();
        assert_eq!(
            (e.kind(), e.to_string()),
            (ErrorKind::InvalidInput, "is a folder".into())
        );
        #[cfg(unix)]
        {
            let e = read_regular(Path::new("/dev/zero")).unwrap_err();
            assert_eq!(
                e.to_string(),
                "is not a regular file (a device, pipe or socket)"
            );
        }
        let binary = dir.path().join("b.relume");
        std::fs::write(&binary, b"RELUME\xff\xfe").unwrap();
        assert_eq!(
            read_regular_to_string(&binary).unwrap_err().to_string(),
            "is not a text file (not valid UTF-8)"
        );
        let missing = read_regular(&dir.path().join("none")).unwrap_err();
        assert_eq!(missing.kind(), ErrorKind::NotFound);
    }
}
