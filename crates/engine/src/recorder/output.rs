//! Writing a recording's lines to disk: the files and the spool, appended in whole lines,
//! synced every [`SYNC_INTERVAL`], cut back on failure (docs/surveying.md#durability).

use super::{io_error, RecorderError, SurveyRecorder, RECORDER_HEADER};
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How often the recorder asks the OS to put what it wrote on the storage itself (`fsync`):
/// a write at least this long after the previous sync is synced, as are a file's first and
/// last lines. A power loss costs at most the calls of the last second
/// (docs/surveying.md#durability).
pub const SYNC_INTERVAL: Duration = Duration::from_secs(1);

/// Where a recording's bytes go: a file, or in tests one that fails on cue.
pub(crate) trait Sink: Write + Send {
    /// Puts what was written on the storage itself (`fdatasync`).
    fn sync(&mut self) -> io::Result<()>;
    /// Cuts the file back to `len` bytes; later writes go after them.
    fn truncate(&mut self, len: u64) -> io::Result<()>;
}

impl Sink for File {
    fn sync(&mut self) -> io::Result<()> {
        self.sync_data()
    }

    fn truncate(&mut self, len: u64) -> io::Result<()> {
        self.set_len(len)
    }
}

/// Creates a new file (never an existing one) to write a recording's lines to.
pub(super) type Opener = Box<dyn Fn(&Path) -> io::Result<Box<dyn Sink>> + Send>;

pub(super) fn open_file(path: &Path) -> io::Result<Box<dyn Sink>> {
    // Append: after a failed write is cut back, the next one goes after the last whole line.
    Ok(Box::new(OpenOptions::new().append(true).create_new(true).open(path)?))
}

/// The file being written: the floor's walk file, or before the first waypoint (`floor`
/// `None`) the spool `DIR/.WALK.pending`, whose lines go into the first walk file.
pub(super) struct Output {
    pub(super) floor: Option<String>,
    pub(super) path: PathBuf,
    pub(super) sink: Box<dyn Sink>,
    /// Bytes of whole lines in the file: what a failed write is cut back to.
    pub(super) len: u64,
    /// Whether the file may hold bytes after `len` (a failed write that could not be cut back).
    pub(super) dirty: bool,
}

impl Output {
    /// Appends `lines` whole, or fails leaving the file as it was (or `dirty`).
    pub(super) fn append(&mut self, lines: &[u8]) -> io::Result<()> {
        if let Err(e) = self.sink.write_all(lines).and_then(|()| self.sink.flush()) {
            self.cut_back();
            return Err(e);
        }
        self.len += lines.len() as u64;
        Ok(())
    }

    /// As [`append`](Self::append), then syncs; lines that cannot be synced are cut back too.
    pub(super) fn append_synced(&mut self, lines: &[u8]) -> io::Result<()> {
        let before = self.len;
        self.append(lines)?;
        self.sink.sync().inspect_err(|_| {
            self.len = before;
            self.cut_back();
        })
    }

    pub(super) fn cut_back(&mut self) {
        self.dirty = self.sink.truncate(self.len).is_err();
    }
}

impl SurveyRecorder {
    /// Appends whole lines to the floor's file, or before the first waypoint to the spool;
    /// syncs when [`SYNC_INTERVAL`] has passed. Fails writing nothing.
    pub(super) fn write(&mut self, lines: &str) -> Result<(), RecorderError> {
        if lines.is_empty() {
            return Ok(());
        }
        let out = match self.out.take() {
            Some(out) => out,
            None => self.open_spool()?,
        };
        let out = self.out.insert(out);
        let written = match self.last_sync.elapsed() >= SYNC_INTERVAL {
            true => out.append_synced(lines.as_bytes()).inspect(|()| self.last_sync = Instant::now()),
            false => out.append(lines.as_bytes()),
        };
        written.map_err(|e| io_error(&out.path, &e)).map_err(|e| self.fail(e))
    }

    /// The spool for what comes before the first waypoint, whose floor is not known yet:
    /// `DIR/.WALK.pending`, on disk like the walk files so that memory stays bounded and a
    /// killed app leaves it.
    pub(super) fn open_spool(&mut self) -> Result<Output, RecorderError> {
        let path = self.directory.join(format!(".{}.pending", self.options.walk_name));
        let opened = std::fs::create_dir_all(&self.directory)
            .map_err(|e| io_error(&self.directory, &e))
            .and_then(|()| (self.open)(&path).map_err(|e| io_error(&path, &e)));
        match opened {
            Ok(sink) => Ok(Output { floor: None, path, sink, len: 0, dirty: false }),
            Err(e) => Err(self.fail(e)),
        }
    }

    /// Refuses a floor whose folder would collide with another's on case-insensitive storage.
    pub(super) fn check_floor_folder(&self, floor: &str) -> Result<(), RecorderError> {
        let Ok(entries) = std::fs::read_dir(&self.directory) else { return Ok(()) };
        let folded = floor.to_lowercase();
        for name in entries.filter_map(|e| e.ok()?.file_name().into_string().ok()) {
            if name != floor && name.to_lowercase() == folded {
                return Err(RecorderError::InvalidName {
                    field: "floor",
                    value: floor.to_owned(),
                    reason: format!(
                        "the folder {name:?} differs from it only in case, and case-insensitive \
                         storage would merge the two"
                    ),
                });
            }
        }
        Ok(())
    }

    /// Begins `floor`'s walk file with its header, what was spooled before the first waypoint
    /// and `first_line`, then ends the previous floor's file. All or nothing: on a failure the
    /// new file is removed and the previous one is as it was.
    pub(super) fn begin_file(
        &mut self,
        floor: &str,
        timestamp_ns: u64,
        first_line: &str,
    ) -> Result<(), RecorderError> {
        let folder = self.directory.join(floor).join("path_data_files");
        if let Err(e) = std::fs::create_dir_all(&folder) {
            return Err(self.fail(io_error(&folder, &e)));
        }
        let path = folder.join(format!("{}-{}.txt", self.options.walk_name, self.stats.files.len() + 1));
        let sink = match (self.open)(&path) {
            Ok(sink) => sink,
            Err(e) => return Err(self.fail(io_error(&path, &e))),
        };
        let mut next = Output { floor: Some(floor.to_owned()), path, sink, len: 0, dirty: false };
        // The first file also holds what came before its waypoint.
        let start_ns = match self.stats.files.is_empty() {
            true => self.first_ns.map_or(timestamp_ns, |f| f.min(timestamp_ns)),
            false => timestamp_ns,
        };
        let (brand, model) = self.options.device.split_once(' ').unwrap_or((&self.options.device, ""));
        let header = format!(
            "#\tstartTime:{start_ns}\n#\tSiteID:{site}\tSiteName:{site}\tFloorId:{floor}\tFloorName:{floor}\n\
             #\tBrand:{brand}\tModel:{model}\n#\t{RECORDER_HEADER}\tVersion:{}\n",
            env!("CARGO_PKG_VERSION"),
            site = self.options.site_id,
        );
        let spool = self.out.as_ref().filter(|out| out.floor.is_none()).map(|out| out.path.clone());
        let mut begun = next.append(header.as_bytes());
        if let (Ok(()), Some(spool)) = (&begun, &spool) {
            begun = copy_spool(spool, &mut next);
        }
        begun = begun.and_then(|()| next.append_synced(first_line.as_bytes()));
        // The previous floor's file ends once the next one holds its first line.
        let end = self.end_line();
        if let (Ok(()), Some(previous)) = (&begun, self.out.as_mut().filter(|out| out.floor.is_some())) {
            if let Err(e) = previous.append_synced(end.as_bytes()) {
                let e = io_error(&previous.path, &e);
                drop(next.sink);
                let _ = std::fs::remove_file(&next.path);
                return Err(self.fail(e));
            }
        }
        if let Err(e) = begun {
            let e = io_error(&next.path, &e);
            drop(next.sink);
            let _ = std::fs::remove_file(&next.path);
            return Err(self.fail(e));
        }
        self.last_sync = Instant::now();
        self.stats.files.push(next.path.clone());
        self.out = Some(next);
        if let Some(spool) = spool {
            // Its lines are in the walk file now; one left behind only repeats them.
            if let Err(e) = std::fs::remove_file(&spool) {
                log::warn!("cannot remove {}: {e}", spool.display());
            }
        }
        Ok(())
    }
}

/// Appends the spool's lines to `out`, a block at a time.
fn copy_spool(spool: &Path, out: &mut Output) -> io::Result<()> {
    let mut from = File::open(spool)?;
    let mut block = vec![0; 64 * 1024];
    loop {
        let n = io::Read::read(&mut from, &mut block)?;
        if n == 0 {
            return Ok(());
        }
        out.append(&block[..n])?;
    }
}
