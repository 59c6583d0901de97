//! The view's channels written to an MCAP file, the recording format Foxglove, the `mcap` CLI
//! and the `mcap` libraries of every language open.
//!
//! In: the channel table ([`crate::schemas::channels`]) and messages by channel index. Out: an
//! MCAP file with one schema per type (`jsonschema`), one channel per topic (`json`), the
//! messages in uncompressed chunks, and at [`McapOut::finish`] the summary (statistics,
//! chunk and message indexes) that lets a viewer seek.
//!
//! What a crash can lose: the chunk being filled. [`McapOut::write`] and [`McapOut::tick`]
//! close the chunk and flush the file every [`FLUSH_EVERY`], so a SIGKILL loses at most that much of the run, and
//! the file up to there reads with a streaming reader (the summary is missing, not the
//! messages). A failed write is reported once and the file is closed there; the caller goes on
//! serving the live view (the poses are the tracker's, not the file's).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::schemas::Channel;

/// How often the chunk is closed and the file flushed: what a crash loses at most.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// An MCAP file that cannot be created or written: one line naming it.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot {action} the MCAP file: {detail}", path.display())]
pub struct McapError {
    pub path: PathBuf,
    /// `create`, `write` or `finish`.
    pub action: &'static str,
    pub detail: String,
}

/// An open MCAP file of the view's channels.
pub struct McapOut {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    /// MCAP channel id of each channel of the table, by index.
    ids: Vec<u16>,
    sequence: u32,
    flushed: Instant,
    messages: u64,
}

impl McapOut {
    /// Creates `path` (replacing a file there) and writes the schemas and channels of `channels`.
    pub fn create(path: &Path, channels: &[Channel]) -> Result<McapOut, McapError> {
        let err = |action, detail: String| McapError {
            path: path.to_path_buf(),
            action,
            detail,
        };
        let file = File::create(path).map_err(|e| err("create", e.to_string()))?;
        let options = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("omnitrack-view ", env!("CARGO_PKG_VERSION")));
        let mut writer = options
            .create(BufWriter::new(file))
            .map_err(|e| err("create", e.to_string()))?;
        let mut ids = Vec::with_capacity(channels.len());
        for c in channels {
            let schema = writer
                .add_schema(c.schema_name, "jsonschema", c.schema.as_bytes())
                .map_err(|e| err("write", e.to_string()))?;
            let id = writer
                .add_channel(schema, &c.topic, "json", &BTreeMap::new())
                .map_err(|e| err("write", e.to_string()))?;
            ids.push(id);
        }
        writer.flush().map_err(|e| err("write", e.to_string()))?;
        Ok(McapOut {
            path: path.to_path_buf(),
            writer,
            ids,
            sequence: 0,
            flushed: Instant::now(),
            messages: 0,
        })
    }

    /// Writes one message of channel `channel` (an index of the table) logged at `log_time_ns`.
    pub fn write(&mut self, channel: usize, log_time_ns: u64, data: &[u8]) -> Result<(), McapError> {
        let Some(&channel_id) = self.ids.get(channel) else {
            return Err(self.error("write", format!("no channel {channel}")));
        };
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(|e| self.error("write", e.to_string()))?;
        self.messages += 1;
        if self.flushed.elapsed() >= FLUSH_EVERY {
            self.flushed = Instant::now();
            self.writer.flush().map_err(|e| self.error("write", e.to_string()))?;
        }
        Ok(())
    }

    /// Closes the chunk and flushes the file if [`FLUSH_EVERY`] has passed since the last flush:
    /// called when no message came for a while, so that a quiet tracker's last poses reach the
    /// disk too.
    pub fn tick(&mut self) -> Result<(), McapError> {
        if self.flushed.elapsed() >= FLUSH_EVERY {
            self.flushed = Instant::now();
            self.writer.flush().map_err(|e| self.error("write", e.to_string()))?;
        }
        Ok(())
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes the summary and the footer, and closes the file.
    pub fn finish(mut self) -> Result<u64, McapError> {
        self.writer.finish().map_err(|e| self.error("finish", e.to_string()))?;
        Ok(self.messages)
    }

    fn error(&self, action: &'static str, detail: String) -> McapError {
        McapError {
            path: self.path.clone(),
            action,
            detail,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schemas::channels;

    #[test]
    fn a_file_reads_back_with_its_schemas_channels_and_messages() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.mcap");
        let table = channels(1);
        let mut out = McapOut::create(&path, &table).unwrap();
        for t in 0..5u64 {
            out.write(0, 1_000 + t, format!("{{\"n\":{t}}}").as_bytes()).unwrap();
        }
        out.write(table.len() - 1, 2_000, b"{}").unwrap();
        assert!(
            out.write(table.len(), 2_000, b"{}").is_err(),
            "a channel that is not in the table"
        );
        assert_eq!(out.finish().unwrap(), 6);

        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        assert_eq!(summary.channels.len(), table.len());
        let stats = summary.stats.expect("statistics");
        assert_eq!(stats.message_count, 6);
        assert_eq!((stats.message_start_time, stats.message_end_time), (1_000, 2_000));
        let messages: Vec<_> = mcap::MessageStream::new(&bytes).unwrap().map(Result::unwrap).collect();
        assert_eq!(messages.len(), 6);
        assert_eq!(messages[0].channel.topic, table[0].topic);
        let schema = messages[0].channel.schema.as_ref().unwrap();
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            (table[0].schema_name, "jsonschema")
        );
        assert_eq!(messages[0].channel.message_encoding, "json");
        assert_eq!(&*messages[4].data, b"{\"n\":4}");
    }

    #[test]
    fn an_unwritable_path_is_one_line_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no such folder").join("run.mcap");
        let e = McapOut::create(&path, &channels(0)).err().unwrap().to_string();
        assert!(e.starts_with(&path.display().to_string()), "{e}");
        assert!(e.contains("cannot create the MCAP file"), "{e}");
        assert!(!e.contains('\n'));
    }
}
