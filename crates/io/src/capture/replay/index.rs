//! A recording's `frames.csv` (docs/interfaces.md, "Recording"), read as a stream: its rows
//! checked (header, numbers, paths that stay inside the recording) in one pass at open, the frames
//! they make kept as small entries, and each frame's rows read back from the file when that frame
//! is replayed.
//!
//! In: the path of `frames.csv`, the recording's directory and rig. Out: a [`FrameIndex`] (the
//! frames in frame-number order, and their rows on demand), or one line naming what is wrong.
//!
//! Why a stream: an index of ten million rows (a day's recording) held as text and parsed rows
//! took 1.8 GB and ten seconds before the first frame. Now memory follows the frames, not the
//! rows: a recording written in (frame, sensor) order, as `record` and the desk tools write it,
//! keeps 32 bytes per frame (where its rows start in the file, how many bytes). Rows in any other
//! order (the format allows it) keep 32 bytes per row so that they can be replayed sorted. The file
//! itself is read through a fixed buffer, and a line longer than any row can sensibly be is
//! skipped and counted without being held.

use crate::capture::{SourceError, SourceStats, WarningKind, WarningLimiter};
use omnitrack_core::rig::Rig;
use std::collections::BTreeMap;
use std::fmt;
use std::fs::File;
use std::io;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// The exact header line of `frames.csv`.
pub const FRAMES_HEADER: &str = "frame,sensor,timestamp_ns,path";

/// A row longer than this is not a row of the format (four short fields): skipped, counted.
const MAX_LINE: usize = 4096;
/// Image directories whose existence is checked at open (one warning each when missing); past
/// this many distinct directories, an index is not laid out as the format describes, and its
/// images are simply checked as they are read.
const MAX_DIRECTORIES: usize = 256;
/// Bytes one frame's rows may span in the file (bad lines between them included) and still be
/// read back in one piece; a frame spread wider is read back row by row (as out of order).
const MAX_FRAME_BYTES: u64 = 64 << 10;

/// One row of a frame, ready to be read.
#[derive(Debug, Clone)]
pub(super) struct Row {
    pub(super) sensor: usize,
    pub(super) timestamp_ns: u64,
    /// Absolute (REC joined with the row's path).
    pub(super) path: PathBuf,
}

/// One frame of the recording: where its rows are and its time.
#[derive(Debug, Clone, Copy)]
pub(super) struct FrameEntry {
    pub(super) frame: u64,
    /// Earliest timestamp of its rows.
    pub(super) timestamp_ns: u64,
    /// In file order: the byte offset of the frame's first line. Sorted: its first [`RowRef`].
    start: u64,
    /// In file order: the bytes of its lines. Sorted: its number of rows.
    len: u32,
}

/// Where one checked row lies in the file (for an index not in (frame, sensor) order).
#[derive(Debug, Clone, Copy)]
struct RowRef {
    frame: u64,
    timestamp_ns: u64,
    offset: u64,
    /// 1-based line number, for the duplicate warning.
    line: u32,
    sensor: u16,
    len: u16,
}

/// The frames of `frames.csv` and a way back to their rows.
#[derive(Debug)]
pub(super) struct FrameIndex {
    path: PathBuf,
    file: File,
    dir: PathBuf,
    sensors: usize,
    frames: Vec<FrameEntry>,
    /// Empty when the file lists its rows in (frame, sensor) order.
    sorted: Vec<RowRef>,
    /// The bytes of the frame being read back.
    bytes: Vec<u8>,
}

/// What is wrong with one row.
enum Bad {
    TooLong,
    NotText,
    FieldCount(usize),
    NotANumber,
    /// The sensor, and the rig's sensor count.
    UnknownSensor(usize, usize),
    EmptyPath,
    Outside(String),
}

impl Bad {
    /// Counts it in its kind's counter.
    fn count(&self, rows: &mut crate::capture::BadRowStats) {
        let counter = match self {
            Bad::TooLong | Bad::NotText => &mut rows.unreadable,
            Bad::FieldCount(_) => &mut rows.field_count,
            Bad::NotANumber => &mut rows.not_a_number,
            Bad::UnknownSensor(..) => &mut rows.unknown_sensor,
            Bad::EmptyPath => &mut rows.empty_path,
            Bad::Outside(_) => &mut rows.outside,
        };
        *counter += 1;
    }
}

impl fmt::Display for Bad {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Bad::TooLong => write!(f, "longer than {MAX_LINE} bytes, not a row of {FRAMES_HEADER}"),
            Bad::NotText => f.write_str("not UTF-8 text"),
            Bad::FieldCount(n) => write!(f, "expected 4 fields ({FRAMES_HEADER}), found {n}"),
            Bad::NotANumber => f.write_str("frame, sensor and timestamp_ns must be non-negative integers"),
            Bad::UnknownSensor(sensor, of) => write!(f, "sensor {sensor} is not in the rig ({of} sensors)"),
            Bad::EmptyPath => f.write_str("empty path"),
            Bad::Outside(p) => write!(f, "path {p:?} leaves the recording (absolute or with ..)"),
        }
    }
}

/// A row's fields, checked.
struct Fields<'a> {
    frame: u64,
    sensor: usize,
    timestamp_ns: u64,
    path: &'a str,
}

fn check_row<'a>(line: &'a [u8], sensors: usize) -> Result<Fields<'a>, Bad> {
    let line = std::str::from_utf8(line).map_err(|_| Bad::NotText)?.trim();
    let mut fields = line.split(',').map(str::trim);
    let (Some(frame), Some(sensor), Some(timestamp_ns), Some(path), None) = (
        fields.next(),
        fields.next(),
        fields.next(),
        fields.next(),
        fields.next(),
    ) else {
        return Err(Bad::FieldCount(line.split(',').count()));
    };
    let (Ok(frame), Ok(sensor), Ok(timestamp_ns)) = (
        frame.parse::<u64>(),
        sensor.parse::<usize>(),
        timestamp_ns.parse::<u64>(),
    ) else {
        return Err(Bad::NotANumber);
    };
    if sensor >= sensors {
        return Err(Bad::UnknownSensor(sensor, sensors));
    }
    if path.is_empty() {
        return Err(Bad::EmptyPath);
    }
    if Path::new(path)
        .components()
        .any(|c| !matches!(c, std::path::Component::Normal(_) | std::path::Component::CurDir))
    {
        return Err(Bad::Outside(path.to_string()));
    }
    Ok(Fields {
        frame,
        sensor,
        timestamp_ns,
        path,
    })
}

/// Reads one line (without its end) into `line`, at most [`MAX_LINE`] bytes of it; returns the
/// bytes the line took in the file (0 at the end) and whether it was longer than that.
fn read_line(reader: &mut impl BufRead, line: &mut Vec<u8>) -> io::Result<(usize, bool)> {
    line.clear();
    let (mut taken, mut long) = (0, false);
    loop {
        let buf = reader.fill_buf()?;
        if buf.is_empty() {
            return Ok((taken, long));
        }
        let (chunk, done) = match buf.iter().position(|&b| b == b'\n') {
            Some(i) => (&buf[..=i], true),
            None => (buf, false),
        };
        let n = chunk.len();
        let content = chunk.strip_suffix(b"\n").unwrap_or(chunk);
        if line.len() + content.len() <= MAX_LINE {
            line.extend_from_slice(content);
        } else {
            long = true;
        }
        reader.consume(n);
        taken += n;
        if done {
            return Ok((taken, long));
        }
    }
}

impl FrameIndex {
    /// Reads `frames.csv` at `path` once: a wrong header is an error; bad rows are skipped,
    /// counted and warned with their line numbers; image directories the rows name but the
    /// recording lacks are warned once each.
    pub(super) fn open(
        path: &Path,
        dir: &Path,
        rig: &Rig,
        stats: &mut SourceStats,
        warnings: &mut WarningLimiter,
    ) -> Result<FrameIndex, SourceError> {
        let io_error = |e: io::Error| SourceError::Io {
            path: path.to_path_buf(),
            message: format!("cannot read frame index: {e}"),
        };
        omnitrack_core::text_file::regular_file_len(path, omnitrack_core::text_file::LARGE_FILE_LIMIT)
            .map_err(io_error)?;
        let file = File::open(path).map_err(io_error)?;
        let mut reader = BufReader::with_capacity(64 << 10, File::open(path).map_err(io_error)?);
        let mut line = Vec::with_capacity(MAX_LINE);

        let (taken, long) = read_line(&mut reader, &mut line).map_err(io_error)?;
        let mut offset = taken as u64;
        let header = std::str::from_utf8(&line)
            .unwrap_or("")
            .trim_start_matches('\u{feff}')
            .trim();
        if header != FRAMES_HEADER || long {
            let found = if header.is_empty() {
                "an empty first line".to_string()
            } else {
                format!("'{}'", header.chars().take(80).collect::<String>())
            };
            return Err(SourceError::Format {
                path: path.to_path_buf(),
                line: Some(1),
                message: format!("expected header '{FRAMES_HEADER}', found {found}"),
            });
        }

        let file_name = path.display().to_string();
        let sensors = rig.sensors.len();
        let mut frames: Vec<FrameEntry> = Vec::new();
        let mut refs: Vec<RowRef> = Vec::new();
        // While the rows come in (frame, sensor) order, only frames are kept; the first row out of
        // order (or a frame spread over too many bytes) turns every row checked so far, and every
        // row after, into a RowRef.
        let mut in_order = true;
        let mut last: Option<(u64, usize)> = None;
        let mut directories: BTreeMap<String, u64> = BTreeMap::new();
        let mut line_no: u32 = 1;
        loop {
            let start = offset;
            let (taken, long) = read_line(&mut reader, &mut line).map_err(io_error)?;
            if taken == 0 {
                break;
            }
            offset += taken as u64;
            line_no = line_no.saturating_add(1);
            if !long && line.iter().all(u8::is_ascii_whitespace) {
                continue;
            }
            let bad = |stats: &mut SourceStats, warnings: &mut WarningLimiter, what: fmt::Arguments<'_>| {
                warnings.warn(
                    stats,
                    WarningKind::BadRow,
                    format_args!("{file_name}:{line_no}: {what}; row skipped"),
                );
            };
            let checked = if long {
                Err(Bad::TooLong)
            } else {
                check_row(&line, sensors)
            };
            let row = match checked {
                Ok(row) => row,
                Err(problem) => {
                    problem.count(&mut stats.bad_rows);
                    bad(stats, warnings, format_args!("{problem}"));
                    continue;
                }
            };
            note_directory(&mut directories, row.path);
            let key = (row.frame, row.sensor);
            if in_order && last == Some(key) {
                stats.bad_rows.duplicate += 1;
                bad(
                    stats,
                    warnings,
                    format_args!(
                        "second row for frame {}, sensor {} (the first is kept)",
                        row.frame, row.sensor
                    ),
                );
                continue;
            }
            let spread = frames
                .last()
                .is_some_and(|f| f.frame == row.frame && offset - f.start > MAX_FRAME_BYTES);
            if in_order && (last.is_some_and(|l| key < l) || spread) {
                in_order = false;
                refs = rescan(path, start, sensors).map_err(io_error)?;
                frames.clear();
            }
            last = Some(key);
            if in_order {
                match frames.last_mut() {
                    // The span may hold bad lines between the frame's rows: they are checked again,
                    // and left out again, when the frame is read back.
                    Some(f) if f.frame == row.frame => {
                        f.len = (offset - f.start) as u32;
                        f.timestamp_ns = f.timestamp_ns.min(row.timestamp_ns);
                    }
                    _ => frames.push(FrameEntry {
                        frame: row.frame,
                        timestamp_ns: row.timestamp_ns,
                        start,
                        len: taken as u32,
                    }),
                }
            } else {
                refs.push(RowRef {
                    frame: row.frame,
                    timestamp_ns: row.timestamp_ns,
                    offset: start,
                    line: line_no,
                    sensor: row.sensor as u16,
                    len: taken as u16,
                });
            }
        }

        if !in_order {
            // Stable: of two rows for one (frame, sensor), the earlier line is kept.
            refs.sort_by_key(|r| (r.frame, r.sensor));
            let mut kept: Vec<RowRef> = Vec::with_capacity(refs.len());
            for r in refs {
                if kept.last().is_some_and(|p| (p.frame, p.sensor) == (r.frame, r.sensor)) {
                    stats.bad_rows.duplicate += 1;
                    warnings.warn(
                        stats,
                        WarningKind::BadRow,
                        format_args!(
                            "{file_name}:{}: second row for frame {}, sensor {} (the first is kept); row skipped",
                            r.line, r.frame, r.sensor
                        ),
                    );
                    continue;
                }
                match frames.last_mut() {
                    Some(f) if f.frame == r.frame => {
                        f.len += 1;
                        f.timestamp_ns = f.timestamp_ns.min(r.timestamp_ns);
                    }
                    _ => frames.push(FrameEntry {
                        frame: r.frame,
                        timestamp_ns: r.timestamp_ns,
                        start: kept.len() as u64,
                        len: 1,
                    }),
                }
                kept.push(r);
            }
            refs = kept;
        }
        frames.shrink_to_fit();
        refs.shrink_to_fit();

        for (relative, count) in &directories {
            let parent = dir.join(relative);
            if !parent.is_dir() {
                warnings.warn(
                    stats,
                    WarningKind::Directory,
                    format_args!(
                        "{}: directory does not exist; its {count} indexed images will count as missing",
                        parent.display()
                    ),
                );
            }
        }

        let longest = if refs.is_empty() {
            frames.iter().map(|f| f.len as usize).max().unwrap_or(0)
        } else {
            MAX_LINE + 1
        };
        Ok(FrameIndex {
            path: path.to_path_buf(),
            file,
            dir: dir.to_path_buf(),
            sensors,
            frames,
            sorted: refs,
            bytes: Vec::with_capacity(longest),
        })
    }

    /// The frames, in frame-number order.
    pub(super) fn frames(&self) -> &[FrameEntry] {
        &self.frames
    }

    /// The rows of `entry` (one of [`frames`](Self::frames)), in sensor order, into the first
    /// entries of `rows`; returns how many. Read back from the file; rows that no longer check (the
    /// file changed since it was opened) are left out, and a file that cannot be read is an error
    /// naming it. The entries of `rows` are reused, paths and all: once every sensor has had a
    /// row, reading a frame allocates nothing.
    pub(super) fn rows(&mut self, entry: &FrameEntry, rows: &mut Vec<Row>) -> Result<usize, SourceError> {
        let path = &self.path;
        let io_error = |e: io::Error| SourceError::Io {
            path: path.clone(),
            message: format!("cannot read frame index: {e}"),
        };
        let mut used = 0;
        let keep = |line: &[u8], frame: u64, rows: &mut Vec<Row>, used: &mut usize| {
            let Ok(f) = check_row(line, self.sensors) else { return };
            // Ascending sensors: a second row of a sensor (a duplicate) is left out as at open.
            if f.frame != frame || (*used > 0 && rows[*used - 1].sensor >= f.sensor) {
                return;
            }
            if *used == rows.len() {
                rows.push(Row {
                    sensor: 0,
                    timestamp_ns: 0,
                    path: PathBuf::new(),
                });
            }
            let row = &mut rows[*used];
            row.sensor = f.sensor;
            row.timestamp_ns = f.timestamp_ns;
            row.path.as_mut_os_string().clear();
            row.path.push(&self.dir);
            row.path.push(f.path);
            *used += 1;
        };
        if self.sorted.is_empty() {
            self.bytes.resize(entry.len as usize, 0);
            self.file.seek(SeekFrom::Start(entry.start)).map_err(io_error)?;
            self.file.read_exact(&mut self.bytes).map_err(io_error)?;
            for line in self.bytes.split(|&b| b == b'\n') {
                keep(line, entry.frame, rows, &mut used);
            }
        } else {
            let first = entry.start as usize;
            for r in &self.sorted[first..first + entry.len as usize] {
                self.bytes.resize(usize::from(r.len), 0);
                self.file.seek(SeekFrom::Start(r.offset)).map_err(io_error)?;
                self.file.read_exact(&mut self.bytes).map_err(io_error)?;
                keep(&self.bytes, entry.frame, rows, &mut used);
            }
        }
        Ok(used)
    }
}

/// Counts the rows per image directory, up to [`MAX_DIRECTORIES`] directories.
fn note_directory(directories: &mut BTreeMap<String, u64>, path: &str) {
    let parent = Path::new(path).parent().and_then(Path::to_str).unwrap_or("");
    if let Some(count) = directories.get_mut(parent) {
        *count += 1;
    } else if directories.len() < MAX_DIRECTORIES {
        directories.insert(parent.to_string(), 1);
    }
}

/// The rows before byte `end` (all in (frame, sensor) order, already checked and counted) as
/// [`RowRef`]s, for an index found out of order at `end`. Read through a second handle, so that
/// the first pass goes on where it was.
fn rescan(path: &Path, end: u64, sensors: usize) -> io::Result<Vec<RowRef>> {
    let mut reader = BufReader::with_capacity(64 << 10, File::open(path)?);
    let mut line = Vec::with_capacity(MAX_LINE);
    let (taken, _) = read_line(&mut reader, &mut line)?;
    let mut offset = taken as u64;
    let mut refs = Vec::new();
    let mut last: Option<(u64, usize)> = None;
    let mut line_no: u32 = 1;
    while offset < end {
        let (taken, long) = read_line(&mut reader, &mut line)?;
        if taken == 0 {
            break;
        }
        let start = offset;
        offset += taken as u64;
        line_no = line_no.saturating_add(1);
        if long {
            continue;
        }
        let Ok(row) = check_row(&line, sensors) else { continue };
        if last == Some((row.frame, row.sensor)) {
            continue;
        }
        last = Some((row.frame, row.sensor));
        refs.push(RowRef {
            frame: row.frame,
            timestamp_ns: row.timestamp_ns,
            offset: start,
            line: line_no,
            sensor: row.sensor as u16,
            len: taken as u16,
        });
    }
    Ok(refs)
}
