//! Reading an input text file (a rig, a model, a trajectory, a config, a frame index) with its
//! kind's size limit, checked before reading.
//!
//! In: a path and the most bytes such a file can sensibly have. Out: its text, or an
//! `io::Error` saying what is wrong with it (the callers put it in their one-line errors).
//!
//! `read_to_string` on a FIFO waits for a writer for ever and on `/dev/zero` fills the memory:
//! only a regular file is read, and only when it is no larger than the limit.

use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// Rig files, tracker configs: a few kilobytes in practice.
pub const SMALL_FILE_LIMIT: u64 = 16 << 20;
/// Models, trajectories, frame indexes: a model of a whole campus is tens of megabytes.
pub const LARGE_FILE_LIMIT: u64 = 4 << 30;

/// The size of the regular file at `path`, if it has at most `limit` bytes; an error saying why
/// not otherwise (for inputs that are not text, such as images, read by their own decoders).
pub fn regular_file_len(path: &Path, limit: u64) -> Result<u64, Error> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(Error::new(ErrorKind::InvalidInput, "not a regular file"));
    }
    if meta.len() > limit {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!(
                "{} bytes, more than such a file can sensibly have ({limit})",
                meta.len()
            ),
        ));
    }
    Ok(meta.len())
}

/// The text of the regular file at `path`, if it has at most `limit` bytes.
pub fn read_text(path: &Path, limit: u64) -> Result<String, Error> {
    let len = regular_file_len(path, limit)?;
    let mut text = String::with_capacity(len as usize);
    // `take`: a file that grows while it is read still stops at the limit.
    std::fs::File::open(path)?.take(limit).read_to_string(&mut text)?;
    Ok(text)
}
