//! A recording's `frames.csv` (docs/interfaces.md, "Recording"): its rows parsed and checked
//! (header, numbers, paths that stay inside the recording), grouped into device frames, and the
//! directories its rows name but the recording lacks counted.
//!
//! In: the text of `frames.csv` and the recording's directory. Out: the rows and the frames they
//! make, or one line naming the row that is wrong.

use super::*;

/// One index row kept after checking.
#[derive(Debug, Clone)]
pub(super) struct Row {
    pub(super) frame: u64,
    pub(super) sensor: usize,
    pub(super) timestamp_ns: u64,
    /// Absolute (REC joined with the row's path).
    pub(super) path: PathBuf,
}

/// One frame of the recording: its rows (sorted by sensor) and its time.
#[derive(Debug, Clone)]
pub(super) struct FrameEntry {
    pub(super) frame: u64,
    pub(super) rows: Range<usize>,
    /// Earliest timestamp of its rows.
    pub(super) timestamp_ns: u64,
}

/// Parses `frames.csv`: a wrong header is an error; bad rows are skipped, counted and warned.
pub(super) fn parse_index(
    text: &str,
    index_path: &Path,
    dir: &Path,
    rig: &Rig,
    stats: &mut SourceStats,
    warnings: &mut WarningLimiter,
) -> Result<Vec<Row>, SourceError> {
    let mut lines = text.lines().enumerate();
    let header = lines
        .next()
        .map(|(_, l)| l.trim_start_matches('\u{feff}').trim())
        .unwrap_or("");
    if header != FRAMES_HEADER {
        let found = if header.is_empty() {
            "an empty first line".to_string()
        } else {
            format!("'{header}'")
        };
        return Err(SourceError::Format {
            path: index_path.to_path_buf(),
            line: Some(1),
            message: format!("expected header '{FRAMES_HEADER}', found {found}"),
        });
    }
    let file = index_path.display();
    let mut seen: HashSet<(u64, usize)> = HashSet::new();
    let mut rows = Vec::new();
    for (i, line) in lines {
        let line_no = i + 1;
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let bad = |stats: &mut SourceStats, warnings: &mut WarningLimiter, what: fmt::Arguments<'_>| {
            warnings.warn(
                stats,
                WarningKind::BadRow,
                format_args!("{file}:{line_no}: {what}; row skipped"),
            );
        };
        if fields.len() != 4 {
            stats.bad_rows.field_count += 1;
            bad(
                stats,
                warnings,
                format_args!("expected 4 fields ({FRAMES_HEADER}), found {}", fields.len()),
            );
            continue;
        }
        let (Ok(frame), Ok(sensor), Ok(timestamp_ns)) = (
            fields[0].parse::<u64>(),
            fields[1].parse::<usize>(),
            fields[2].parse::<u64>(),
        ) else {
            stats.bad_rows.not_a_number += 1;
            bad(
                stats,
                warnings,
                format_args!("frame, sensor and timestamp_ns must be non-negative integers"),
            );
            continue;
        };
        if sensor >= rig.sensors.len() {
            stats.bad_rows.unknown_sensor += 1;
            bad(
                stats,
                warnings,
                format_args!("sensor {sensor} is not in the rig ({} sensors)", rig.sensors.len()),
            );
            continue;
        }
        if fields[3].is_empty() {
            stats.bad_rows.empty_path += 1;
            bad(stats, warnings, format_args!("empty path"));
            continue;
        }
        let relative = Path::new(fields[3]);
        if relative
            .components()
            .any(|c| !matches!(c, std::path::Component::Normal(_) | std::path::Component::CurDir))
        {
            stats.bad_rows.outside += 1;
            bad(
                stats,
                warnings,
                format_args!("path {:?} leaves the recording (absolute or with ..)", fields[3]),
            );
            continue;
        }
        if !seen.insert((frame, sensor)) {
            stats.bad_rows.duplicate += 1;
            bad(
                stats,
                warnings,
                format_args!("second row for frame {frame}, sensor {sensor} (the first is kept)"),
            );
            continue;
        }
        rows.push(Row {
            frame,
            sensor,
            timestamp_ns,
            path: dir.join(fields[3]),
        });
    }
    Ok(rows)
}

/// Groups rows sorted by (frame, sensor) into frames.
pub(super) fn group_frames(rows: &[Row]) -> Vec<FrameEntry> {
    let mut frames: Vec<FrameEntry> = Vec::new();
    for (i, row) in rows.iter().enumerate() {
        match frames.last_mut() {
            Some(f) if f.frame == row.frame => {
                f.rows.end = i + 1;
                f.timestamp_ns = f.timestamp_ns.min(row.timestamp_ns);
            }
            _ => frames.push(FrameEntry {
                frame: row.frame,
                rows: i..i + 1,
                timestamp_ns: row.timestamp_ns,
            }),
        }
    }
    frames
}

/// Warns once per image directory that does not exist (its images then count as missing, frame by
/// frame).
pub(super) fn warn_missing_directories(rows: &[Row], stats: &mut SourceStats, warnings: &mut WarningLimiter) {
    let mut checked: HashSet<&Path> = HashSet::new();
    for row in rows {
        let Some(parent) = row.path.parent() else { continue };
        if checked.insert(parent) && !parent.is_dir() {
            let count = rows.iter().filter(|r| r.path.parent() == Some(parent)).count();
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
}
