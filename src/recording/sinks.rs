use std::path::PathBuf;

use rerun::external::re_uri;
use rerun::sink::LogSink;
use rerun::{RecordingStream, RecordingStreamBuilder, RecordingStreamError};

use crate::Error;

use super::RecordingResult;
use super::layout::{LayoutParts, send_layout};

/// Where a CLI run sends its recording. At least one of the three enables recording.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RecordingArgs {
    /// Save a Rerun recording of every stage to this .rrd file (open with Rerun viewer 0.36.3).
    #[arg(long, value_name = "FILE")]
    pub rrd: Option<PathBuf>,
    /// Spawn a Rerun viewer (`rerun` 0.36.3 on PATH) and stream the recording to it.
    #[arg(long)]
    pub spawn: bool,
    /// Stream the recording to a running viewer (default rerun+http://127.0.0.1:9876/proxy).
    #[arg(long, value_name = "URL", num_args = 0..=1,
          default_missing_value = rerun::DEFAULT_CONNECT_URL)]
    pub connect: Option<String>,
}

impl RecordingArgs {
    /// Opens the requested sinks (creating the .rrd's directory) and sends the viewer layout
    /// of `layout` ([`send_layout`]); `None` when no sink was requested.
    pub fn open(
        &self,
        application_id: &'static str,
        layout: LayoutParts,
    ) -> RecordingResult<Option<RecordingStream>> {
        let rec = self.open_sinks(application_id)?;
        if let Some(rec) = &rec {
            send_layout(rec, layout)?;
            let what = [
                self.rrd.as_ref().map(|p| p.display().to_string()),
                self.spawn.then(|| "the spawned viewer".to_string()),
                self.connect.clone(),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join(" and ");
            if let Ok(mut opened) = OPENED.lock() {
                opened.push((what, rec.clone()));
            }
        }
        Ok(rec)
    }

    fn open_sinks(&self, application_id: &'static str) -> RecordingResult<Option<RecordingStream>> {
        if let Some(dir) = self.rrd.as_deref().and_then(std::path::Path::parent)
            && !dir.as_os_str().is_empty()
        {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        if let Some(path) = &self.rrd {
            unlink_for_rewrite(path);
        }
        let builder = RecordingStreamBuilder::new(application_id);
        match (&self.rrd, self.spawn, &self.connect) {
            (None, false, None) => return Ok(None),
            (Some(path), false, None) => return Ok(Some(builder.save(path)?)),
            _ => {}
        }
        let mut sinks: Vec<Box<dyn LogSink>> = Vec::new();
        if let Some(path) = &self.rrd {
            sinks.push(Box::new(
                rerun::sink::FileSink::new(path).map_err(RecordingStreamError::from)?,
            ));
        }
        let mut urls = Vec::new();
        if self.spawn {
            let info = rerun::spawn(&rerun::SpawnOptions::default())
                .map_err(RecordingStreamError::from)?;
            urls.push(format!("rerun+http://127.0.0.1:{}/proxy", info.port));
        }
        if let Some(url) = &self.connect {
            urls.push(url.clone());
        }
        for url in urls {
            let re_uri::RedapUri::Proxy(uri) = url
                .parse::<re_uri::RedapUri>()
                .map_err(RecordingStreamError::from)?
            else {
                return Err(RecordingStreamError::NotAProxyEndpoint.into());
            };
            sinks.push(Box::new(rerun::sink::GrpcSink::new(uri)));
        }
        Ok(Some(builder.set_sinks(sinks)?))
    }
}

/// The recordings [`RecordingArgs::open`] opened in this process, for [`finish_opened`].
static OPENED: std::sync::Mutex<Vec<(String, RecordingStream)>> = std::sync::Mutex::new(Vec::new());

/// Flushes every recording [`RecordingArgs::open`] opened (waiting at most `timeout` for
/// each) and closes them; returns one message per recording that could not be written or
/// streamed (a full disk, a viewer that is not listening, no display for `--spawn`). The
/// command line turns these into a non-zero exit: a recording that did not happen is said.
pub fn finish_opened(timeout: std::time::Duration) -> Vec<String> {
    let opened = match OPENED.lock() {
        Ok(mut o) => std::mem::take(&mut *o),
        Err(_) => return Vec::new(),
    };
    let mut failures = Vec::new();
    for (what, rec) in opened {
        super::layout::forget(&rec);
        if let Err(e) = rec.flush_with_timeout(timeout) {
            failures.push(format!("the recording to {what} was not completed: {e}"));
            // Dropping the stream would wait for its sink forever: a gRPC sink whose viewer
            // is not listening holds at most 100 messages and blocks on the next one. The
            // stream is left to the process's exit instead.
            std::mem::forget(rec);
        }
    }
    failures
}

/// Removes an existing regular, singly linked file at `path`, so that the recording goes to
/// a new file instead of over a truncated one. Truncating costs more: ext4 frees the old
/// blocks inside the truncating call, and on close starts writing back a file that was
/// truncated and rewritten (its `auto_da_alloc` safeguard); opening an 8 MB recording's
/// path took about 2 ms longer that way (`examples/recording_overhead.rs`). Symlinks and
/// hard-linked files are left alone (the sink truncates them, as `File::create` does), and
/// so is a file that cannot be removed.
fn unlink_for_rewrite(path: &std::path::Path) {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let Ok(m) = std::fs::symlink_metadata(path)
            && m.file_type().is_file()
            && m.nlink() == 1
        {
            std::fs::remove_file(path).ok();
        }
    }
    #[cfg(not(unix))]
    let _ = path;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An existing recording is replaced by a new file (a new inode), not truncated; a
    /// symlink is left in place, so the sink writes through it.
    #[cfg(unix)]
    #[test]
    fn rrd_is_written_to_a_new_file_but_symlinks_are_kept() {
        use std::os::unix::fs::MetadataExt;
        let dir = std::env::temp_dir().join(format!("rank3-unlink-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (file, link) = (dir.join("a.rrd"), dir.join("b.rrd"));
        std::fs::write(&file, b"old").unwrap();
        let before = std::fs::metadata(&file).unwrap().ino();
        // Keep the old inode alive, so that the new file cannot reuse its number.
        let _old = std::fs::File::open(&file).unwrap();
        unlink_for_rewrite(&file);
        assert!(!file.exists());
        std::fs::write(&file, b"new").unwrap();
        assert_ne!(std::fs::metadata(&file).unwrap().ino(), before);
        std::os::unix::fs::symlink(&file, &link).unwrap();
        unlink_for_rewrite(&link);
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
