//! The shared-memory transport of external stages: one file in `/dev/shm` (or the
//! temporary folder where there is none), mapped by relume and by the program, sized
//! for a frame's inputs followed by its outputs at the recording's image size. relume
//! copies the inputs in before a request and the outputs out after the reply; only the
//! metas travel over the pipe. A pipe moves 15 MB in 10-30 ms here; two memory copies
//! take a few.
//!
//! The file is created readable and writable by its owner alone and removed as soon as
//! the program has mapped it (or when this is dropped), so nothing is left behind,
//! even by a run that is killed later.

use memmap2::MmapMut;
use std::path::PathBuf;

pub struct SharedMemory {
    /// Until the program has mapped the file.
    path: Option<PathBuf>,
    map: MmapMut,
    /// Where the outputs' region starts.
    pub output_offset: usize,
}

impl SharedMemory {
    /// A region of `input_bytes + output_bytes`, named after the stage.
    pub fn create(stage: &str, input_bytes: usize, output_bytes: usize) -> std::io::Result<Self> {
        use std::os::unix::fs::OpenOptionsExt;
        static COUNT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let dir = PathBuf::from("/dev/shm");
        let dir = if dir.is_dir() {
            dir
        } else {
            std::env::temp_dir()
        };
        let stage: String = stage
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .take(40)
            .collect();
        let n = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = dir.join(format!("relume-{}-{stage}-{n}", std::process::id()));
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(&path)?;
        let size = input_bytes + output_bytes;
        let mapped = file.set_len(size as u64).and_then(|()| {
            // SAFETY: the file is this process's own, just created; the one other process
            // that maps it (the program) writes only the outputs' region, and only between
            // a request and its reply, while relume does not read it.
            unsafe { MmapMut::map_mut(&file) }
        });
        match mapped {
            Ok(map) => Ok(SharedMemory {
                path: Some(path),
                map,
                output_offset: input_bytes,
            }),
            Err(e) => {
                let _ = std::fs::remove_file(&path);
                Err(e)
            }
        }
    }

    /// The file's path, while it exists.
    pub fn path(&self) -> Option<&std::path::Path> {
        self.path.as_deref()
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// Removes the file once the program has mapped it: the mappings stay.
    pub fn unlink(&mut self) {
        if let Some(path) = self.path.take() {
            let _ = std::fs::remove_file(path);
        }
    }

    /// The region `[offset, offset + len)`, if it lies inside.
    pub fn slice(&self, offset: usize, len: usize) -> Option<&[u8]> {
        self.map.get(offset..offset.checked_add(len)?)
    }

    /// Copies `bytes` to `offset` (in parallel: two copies of 15 MB are most of the
    /// transport's time). The caller has sized the region for it.
    pub fn write(&mut self, offset: usize, bytes: &[u8]) {
        use rayon::prelude::*;
        const PIECE: usize = 1 << 20;
        self.map[offset..offset + bytes.len()]
            .par_chunks_mut(PIECE)
            .zip(bytes.par_chunks(PIECE))
            .for_each(|(to, from)| to.copy_from_slice(from));
    }
}

impl Drop for SharedMemory {
    fn drop(&mut self) {
        self.unlink();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_region_holds_what_is_written_and_leaves_no_file() {
        let mut shm = SharedMemory::create("a stage/1", 8, 4).unwrap();
        let path = shm.path().unwrap().to_path_buf();
        assert!(
            path.file_name()
                .unwrap()
                .to_str()
                .unwrap()
                .contains("a_stage_1")
        );
        assert_eq!((shm.len(), shm.output_offset), (12, 8));
        shm.write(2, &[1, 2, 3]);
        assert_eq!(shm.slice(1, 4), Some(&[0, 1, 2, 3][..]));
        assert_eq!(shm.slice(10, 3), None);
        assert_eq!(shm.slice(usize::MAX, 2), None);
        shm.unlink();
        assert!(!path.exists());
        assert_eq!(
            shm.slice(2, 1),
            Some(&[1][..]),
            "the mapping outlives the file"
        );
        let other = SharedMemory::create("b", 1, 1).unwrap();
        let path = other.path().unwrap().to_path_buf();
        drop(other);
        assert!(!path.exists());
    }
}
