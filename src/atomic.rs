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

/// A fresh temporary path for `path`, in its folder.
fn temp_for(path: &Path) -> PathBuf {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    temp_path(dir, &name)
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
/// documentation): a [`FileSet`] of one. Errors name `path`, also when writing its
/// temporary file failed (a full disk, a file-size limit): the user asked for `path`, not
/// for the temporary name.
pub fn write_with(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let mut set = FileSet::new();
    set.add_with(path, body)?;
    set.commit()
}

/// [`write_with`] for bytes already in memory.
pub fn write(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_with(path, |w| std::io::Write::write_all(w, bytes.as_ref()))
}

/// A set of files written together: each is written whole to its temporary file as it is
/// [`add`](Self::add)ed, and none replaces its destination until [`commit`](Self::commit)
/// renames them all. A failure while writing (a full disk, a file-size limit) therefore
/// leaves every destination as it was — not new small files beside an earlier run's large
/// ones. Temporary files not committed are removed when the set is dropped. (A failure of
/// a `rename` itself, after the data are on disk, can still leave the set part renamed.)
#[derive(Debug, Default)]
pub struct FileSet {
    /// (temporary file, destination), in the order added.
    staged: Vec<(PathBuf, PathBuf)>,
}

impl FileSet {
    pub fn new() -> Self {
        Self::default()
    }

    /// Writes `bytes` to a temporary file beside `path`. Errors name `path`.
    pub fn add(&mut self, path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
        self.add_with(path, |w| std::io::Write::write_all(w, bytes.as_ref()))
    }

    /// Writes a temporary file beside `path` with `body`. Errors name `path`.
    pub fn add_with(
        &mut self,
        path: &Path,
        body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
    ) -> Result<()> {
        let tmp = temp_for(path);
        match write_file(&tmp, body) {
            Ok(()) => {
                self.staged.push((tmp, path.to_path_buf()));
                Ok(())
            }
            Err(e) => {
                let _ = std::fs::remove_file(&tmp);
                Err(match e {
                    Error::Io { source, .. } => Error::io(path, source),
                    e => e,
                })
            }
        }
    }

    /// Renames every staged file into place, in the order added. When a rename fails, the
    /// files not renamed yet are removed (by `Drop`).
    pub fn commit(mut self) -> Result<()> {
        while !self.staged.is_empty() {
            let (tmp, dest) = self.staged.remove(0);
            if let Err(e) = std::fs::rename(&tmp, &dest) {
                let _ = std::fs::remove_file(&tmp);
                return Err(Error::io(&dest, e));
            }
        }
        Ok(())
    }
}

impl Drop for FileSet {
    fn drop(&mut self) {
        for (tmp, _) in &self.staged {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_set_replaces_all_or_nothing() {
        let dir = std::env::temp_dir().join(format!("rank3-fileset-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (a, b) = (dir.join("a.txt"), dir.join("b.txt"));
        write(&a, "old a").unwrap();
        write(&b, "old b").unwrap();
        // The second file cannot be written (its folder does not exist): nothing replaced.
        let mut set = FileSet::new();
        set.add(&a, "new a").unwrap();
        let bad = dir.join("missing").join("c.txt");
        match set.add(&bad, "new c") {
            Err(Error::Io { path, .. }) => assert_eq!(path, bad),
            r => panic!("{r:?}"),
        }
        drop(set);
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        let mut set = FileSet::new();
        set.add(&a, "new a").unwrap();
        set.add(&b, "new b").unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        set.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "new a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b");
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(left.len(), 2, "temporary files left: {left:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

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
