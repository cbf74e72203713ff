//! Whole-file writes: a reader sees the old file or the new one, never half of one.
//!
//! Each file is written to a temporary name in its own folder (`.NAME.rank3-tmp-PID-N`),
//! flushed to disk (`sync_all`) and renamed over the destination (atomic within a file
//! system, POSIX `rename(2)`). A failure at any point — a full disk, an I/O error, a
//! serializer error — removes the temporary file and leaves the destination untouched.
//!
//! Complexity: the write itself plus one `fsync` and one `rename` per file.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::{Error, Result};

/// A fresh temporary path for `name` in `dir` (hidden, unique per process and call).
pub(crate) fn temp_path(dir: &Path, name: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    dir.join(format!(".{name}.rank3-tmp-{}-{n}", std::process::id()))
}

/// Creates `path`, writes it with `body` and flushes it to disk.
pub(crate) fn write_file(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let file = File::create(path).map_err(|e| Error::io(path, e))?;
    let mut w = BufWriter::new(file);
    body(&mut w).map_err(|e| Error::io(path, e))?;
    let file = w
        .into_inner()
        .map_err(|e| Error::io(path, e.into_error()))?;
    file.sync_all().map_err(|e| Error::io(path, e))
}

/// Writes `path` with `body` through a temporary file renamed into place (see the module
/// documentation). Errors name `path`, also when writing its temporary file failed (a full
/// disk, a file-size limit): the user asked for `path`, not for the temporary name.
pub fn write_with(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    let tmp = temp_path(dir, &name);
    let done = write_file(&tmp, body)
        .map_err(|e| match e {
            Error::Io { source, .. } => Error::io(path, source),
            e => e,
        })
        .and_then(|()| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e)));
    if done.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    done
}

/// [`write_with`] for bytes already in memory.
pub fn write(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_with(path, |w| std::io::Write::write_all(w, bytes.as_ref()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = std::env::temp_dir().join(format!("rank3-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("out.txt");
        write(&path, "old complete file\n").unwrap();
        // The body fails half-way (as a full disk would).
        let r = write_with(&path, |w| {
            std::io::Write::write_all(w, b"new but")?;
            Err(std::io::Error::other("disk full"))
        });
        match &r {
            Err(Error::Io { path: p, .. }) => assert_eq!(p, &path, "the error names the file"),
            r => panic!("{r:?}"),
        }
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "old complete file\n"
        );
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(left.len(), 1, "a temporary file was left behind");
        write(&path, "new complete file\n").unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "new complete file\n"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
