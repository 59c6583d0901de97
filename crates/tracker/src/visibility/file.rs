//! The visibility table's file (the parent module's doc, "File"): magic bytes, a postcard
//! [`TableHeader`], the postcard body with delta-coded sets, and a checksum; the model's hash a
//! table is tied to.
//!
//! In: a [`VisibilityTable`] or the bytes of a file. Out: the bytes, or the table with every
//! inconsistency (another model, a damaged file, other build settings) an error naming it.

use super::{TableHeader, VisibilityError, VisibilityTable, NO_NODE};
use nalgebra::Point3;
use omnitrack_core::model::Model;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Bumped whenever the file layout changes.
pub const FORMAT_VERSION: u32 = 2;

/// First bytes of every table file.
pub const MAGIC: [u8; 8] = *b"OMNIVIS\n";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct TableBody {
    /// Per lookup cell (x fastest, then y, then layer): the serving node, or [`NO_NODE`].
    cell_node: Vec<u32>,
    /// Per node: its own grid cell.
    node_cell: Vec<u32>,
    /// Per node: index into `sets`.
    node_set: Vec<u32>,
    /// Per distinct set: delta-coded sorted face ids, then segment ids.
    set_faces: Vec<Vec<u32>>,
    set_segments: Vec<Vec<u32>>,
    /// Per model segment: indices of its end points in `Model::vertices` ([`NO_NODE`] if none).
    segment_vertices: Vec<[u32; 2]>,
}

/// FNV-1a (64-bit) of the model's geometry: vertex coordinates, faces (vertex indices and OBJ
/// numbers) and segments (end points and faces). Any edit of the model changes it.
pub fn model_hash(model: &Model) -> u64 {
    let mut h = Fnv::new();
    h.u64(model.vertices.len() as u64);
    for v in &model.vertices {
        for c in [v.x, v.y, v.z] {
            h.u64(c.to_bits());
        }
    }
    h.u64(model.faces.len() as u64);
    for f in &model.faces {
        h.u64(f.vertices.len() as u64);
        for &i in &f.vertices {
            h.u64(i as u64);
        }
        h.u64(f.obj_number as u64);
    }
    h.u64(model.segments.len() as u64);
    for s in &model.segments {
        for c in [s.a.x, s.a.y, s.a.z, s.b.x, s.b.y, s.b.z] {
            h.u64(c.to_bits());
        }
        h.u64(s.faces.len() as u64);
        for &f in &s.faces {
            h.u64(f as u64);
        }
    }
    h.0
}

/// FNV-1a over bytes.
fn checksum(bytes: &[u8]) -> u64 {
    let mut h = Fnv::new();
    for &b in bytes {
        h.0 ^= b as u64;
        h.0 = h.0.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h.0
}

struct Fnv(u64);

impl Fnv {
    fn new() -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn u64(&mut self, x: u64) {
        for b in x.to_le_bytes() {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// Per segment, the indices of its end points among the model's vertices (exact positions;
/// [`NO_NODE`] for an end point that is not a model vertex).
pub fn segment_vertex_ids(model: &Model) -> Vec<[u32; 2]> {
    let key = |p: &Point3<f64>| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    let index: HashMap<[u64; 3], u32> = model
        .vertices
        .iter()
        .enumerate()
        .map(|(i, p)| (key(p), i as u32))
        .collect();
    model
        .segments
        .iter()
        .map(|s| {
            [
                index.get(&key(&s.a)).copied().unwrap_or(NO_NODE),
                index.get(&key(&s.b)).copied().unwrap_or(NO_NODE),
            ]
        })
        .collect()
}

fn delta_encode(ids: &[u32]) -> Vec<u32> {
    let mut prev = 0u32;
    ids.iter()
        .enumerate()
        .map(|(i, &x)| {
            let d = if i == 0 { x } else { x - prev - 1 };
            prev = x;
            d
        })
        .collect()
}

fn delta_decode(deltas: &[u32], out: &mut Vec<u32>) -> Option<()> {
    let mut prev = 0u32;
    for (i, &d) in deltas.iter().enumerate() {
        let x = if i == 0 {
            d
        } else {
            prev.checked_add(d)?.checked_add(1)?
        };
        out.push(x);
        prev = x;
    }
    Some(())
}

/// The raw result of a build, before it is packed into a [`VisibilityTable`].
#[derive(Debug, Clone, PartialEq)]
pub struct RawTable {
    pub header: TableHeader,
    pub cell_node: Vec<u32>,
    pub node_cell: Vec<u32>,
    /// Per node: sorted visible face ids and sorted visible segment ids.
    pub node_faces: Vec<Vec<u32>>,
    pub node_segments: Vec<Vec<u32>>,
    pub segment_vertices: Vec<[u32; 2]>,
}

impl VisibilityTable {
    /// Packs per-node sets: identical sets are stored once.
    pub fn from_raw(raw: RawTable) -> VisibilityTable {
        let mut body = TableBody {
            cell_node: raw.cell_node,
            node_cell: raw.node_cell,
            node_set: Vec::with_capacity(raw.node_faces.len()),
            set_faces: Vec::new(),
            set_segments: Vec::new(),
            segment_vertices: raw.segment_vertices,
        };
        let mut seen: HashMap<(&[u32], &[u32]), u32> = HashMap::new();
        for (f, s) in raw.node_faces.iter().zip(&raw.node_segments) {
            let next = seen.len() as u32;
            let id = *seen.entry((f.as_slice(), s.as_slice())).or_insert_with(|| {
                body.set_faces.push(delta_encode(f));
                body.set_segments.push(delta_encode(s));
                next
            });
            body.node_set.push(id);
        }
        Self::from_parts(raw.header, body).expect("a freshly built table is consistent")
    }

    fn from_parts(header: TableHeader, body: TableBody) -> Result<VisibilityTable, String> {
        if header.dims.contains(&0) || header.spacing_m.is_nan() || header.spacing_m <= 0.0 {
            return Err("empty or invalid grid".into());
        }
        let m = header.lookup_subdivisions as usize;
        let cells = header.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d as usize));
        let lookup = cells.and_then(|c| c.checked_mul(m)?.checked_mul(m));
        let (Some(cells), Some(lookup)) = (cells, lookup) else {
            return Err("grid too large".into());
        };
        if m == 0 || body.cell_node.len() != lookup {
            return Err(format!(
                "{} lookup cells stored, header says {lookup}",
                body.cell_node.len()
            ));
        }
        let nodes = header.node_count as usize;
        if body.node_cell.len() != nodes || body.node_set.len() != nodes {
            return Err("node arrays do not match the node count".into());
        }
        if header.heights_m.len() != header.dims[2] as usize || header.heights_m.iter().any(|h| !h.is_finite()) {
            return Err("inconsistent grid header".into());
        }
        if body.segment_vertices.len() != header.segment_count as usize {
            return Err("segment end points do not match the segment count".into());
        }
        if body.cell_node.iter().any(|&n| n != NO_NODE && n as usize >= nodes)
            || body.node_cell.iter().any(|&c| c as usize >= cells)
            || body.node_set.iter().any(|&s| s as usize >= body.set_faces.len())
            || body.set_faces.len() != body.set_segments.len()
        {
            return Err("index out of range".into());
        }
        let mut t = VisibilityTable {
            header,
            cell_node: body.cell_node,
            node_cell: body.node_cell,
            node_set: body.node_set,
            set_start: Vec::with_capacity(body.set_faces.len() + 1),
            faces: Vec::new(),
            segments: Vec::new(),
            vertices: Vec::new(),
            segment_vertices: body.segment_vertices,
        };
        let mut verts = Vec::new();
        for (f, s) in body.set_faces.iter().zip(&body.set_segments) {
            t.set_start
                .push([t.faces.len() as u32, t.segments.len() as u32, t.vertices.len() as u32]);
            let s0 = t.segments.len();
            delta_decode(f, &mut t.faces).ok_or("bad face list")?;
            delta_decode(s, &mut t.segments).ok_or("bad segment list")?;
            verts.clear();
            for &seg in &t.segments[s0..] {
                let ends = t.segment_vertices.get(seg as usize).ok_or("segment id out of range")?;
                verts.extend(ends.iter().copied().filter(|&v| v != NO_NODE));
            }
            verts.sort_unstable();
            verts.dedup();
            t.vertices.extend_from_slice(&verts);
        }
        if t.faces.iter().any(|&f| f >= t.header.face_count) {
            return Err("face id out of range".into());
        }
        if t.vertices.iter().any(|&v| v >= t.header.vertex_count) {
            return Err("vertex id out of range".into());
        }
        t.set_start
            .push([t.faces.len() as u32, t.segments.len() as u32, t.vertices.len() as u32]);
        Ok(t)
    }

    fn body(&self) -> TableBody {
        let sets = self.set_start.len() - 1;
        let mut body = TableBody {
            cell_node: self.cell_node.clone(),
            node_cell: self.node_cell.clone(),
            node_set: self.node_set.clone(),
            set_faces: Vec::with_capacity(sets),
            set_segments: Vec::with_capacity(sets),
            segment_vertices: self.segment_vertices.clone(),
        };
        for i in 0..sets {
            let (a, b) = (self.set_start[i], self.set_start[i + 1]);
            body.set_faces
                .push(delta_encode(&self.faces[a[0] as usize..b[0] as usize]));
            body.set_segments
                .push(delta_encode(&self.segments[a[1] as usize..b[1] as usize]));
        }
        body
    }

    /// The file's bytes: magic, header, body, and the FNV-1a checksum of all before it (so a
    /// damaged file is refused, not read as another table).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.extend(postcard::to_stdvec(&self.header).expect("header serialises"));
        out.extend(postcard::to_stdvec(&self.body()).expect("body serialises"));
        let sum = checksum(&out);
        out.extend(sum.to_le_bytes());
        out
    }

    /// Parses a table file's bytes without checking it against a model; `file` names it in errors.
    pub fn from_bytes(bytes: &[u8], file: &str) -> Result<VisibilityTable, VisibilityError> {
        let format = |message: String| VisibilityError::Format {
            file: file.to_string(),
            message,
        };
        if bytes.len() < MAGIC.len() || bytes[..MAGIC.len()] != MAGIC {
            return Err(format("missing the OMNIVIS magic bytes".into()));
        }
        let rest = &bytes[MAGIC.len()..];
        // The version is the header's first field: read it alone first so that a table of
        // another version is reported as such, not as garbage.
        let (version, _) = postcard::take_from_bytes::<u32>(rest).map_err(|e| format(format!("header: {e}")))?;
        if version != FORMAT_VERSION {
            return Err(VisibilityError::Version {
                file: file.to_string(),
                found: version,
                expected: FORMAT_VERSION,
            });
        }
        // Everything after the version is checked before it is parsed.
        let Some(split) = bytes.len().checked_sub(8).filter(|&n| n >= MAGIC.len()) else {
            return Err(format("too short for its checksum".into()));
        };
        let (content, sum) = bytes.split_at(split);
        let stored = u64::from_le_bytes(sum.try_into().expect("8 bytes"));
        if checksum(content) != stored {
            return Err(VisibilityError::Invalid {
                file: file.to_string(),
                message: "corrupt visibility table: the checksum does not match (the file is damaged or \
                          truncated); rebuild it with `omnitrack visibility build`"
                    .into(),
            });
        }
        let rest = &content[MAGIC.len()..];
        let (header, rest) =
            postcard::take_from_bytes::<TableHeader>(rest).map_err(|e| format(format!("header: {e}")))?;
        let (body, rest) = postcard::take_from_bytes::<TableBody>(rest).map_err(|e| format(format!("body: {e}")))?;
        if !rest.is_empty() {
            return Err(format(format!("{} trailing bytes", rest.len())));
        }
        Self::from_parts(header, body).map_err(|message| VisibilityError::Invalid {
            file: file.to_string(),
            message: format!("corrupt visibility table: {message}"),
        })
    }

    /// Writes the table file.
    pub fn save(&self, path: &Path) -> Result<(), VisibilityError> {
        // Written beside it and renamed over it: a reader never sees half a table, a crash leaves
        // the old one, and a symbolic link at `path` is replaced, not written through (the cache
        // beside a model must not overwrite whatever a link there points to).
        // Serialised before any file exists: a process that dies here (out of memory aborts, it
        // does not unwind) leaves nothing behind.
        let bytes = self.to_bytes();
        remove_stale_partials(path);
        let temporary = partial_path(path, std::process::id());
        let written = (|| {
            let mut f = std::fs::File::create(&temporary)?;
            std::io::Write::write_all(&mut f, &bytes)?;
            f.sync_all()?;
            std::fs::rename(&temporary, path)
        })();
        written.map_err(|e| {
            let _ = std::fs::remove_file(&temporary);
            VisibilityError::Io {
                file: path.display().to_string(),
                action: "write visibility table",
                message: e.to_string(),
            }
        })
    }

    /// Reads a table file without checking it against a model.
    pub fn load_unchecked(path: &Path) -> Result<VisibilityTable, VisibilityError> {
        let file = path.display().to_string();
        let read = || {
            // A device or a FIFO is no table (and /dev/zero would never end).
            if !std::fs::metadata(path)?.is_file() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "not a regular file",
                ));
            }
            std::fs::read(path)
        };
        let bytes = read().map_err(|e| VisibilityError::Io {
            file: file.clone(),
            action: "read visibility table",
            message: e.to_string(),
        })?;
        Self::from_bytes(&bytes, &file)
    }

    /// Reads a table file and checks that it was built for `model`.
    pub fn load(path: &Path, model: &Model) -> Result<VisibilityTable, VisibilityError> {
        let table = Self::load_unchecked(path)?;
        table.check_model(model, &path.display().to_string(), "this model")?;
        Ok(table)
    }

    /// An error unless the table was built for `model`; `file` names the table, `model_name` the
    /// model in the message.
    pub fn check_model(&self, model: &Model, file: &str, model_name: &str) -> Result<(), VisibilityError> {
        let hash = model_hash(model);
        if hash != self.header.model_hash {
            return Err(VisibilityError::ModelMismatch {
                file: file.to_string(),
                model: model_name.to_string(),
                table_hash: self.header.model_hash,
                model_hash: hash,
            });
        }
        Ok(())
    }
}

/// Where process `pid` writes the table for `path` before renaming it into place.
fn partial_path(path: &Path, pid: u32) -> PathBuf {
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(format!(".partial-{pid}"));
    PathBuf::from(temporary)
}

/// Removes the `<path>.partial-<pid>` files of processes that no longer run (killed while
/// writing: SIGKILL and power loss run no clean-up), so that they do not pile up beside the
/// model. A process that still runs may be writing its own: it is left alone. Where `/proc`
/// cannot tell (another OS), nothing is removed.
fn remove_stale_partials(path: &Path) {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name().and_then(|n| n.to_str())) else {
        return;
    };
    if !Path::new("/proc/self").exists() {
        return;
    }
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let prefix = format!("{name}.partial-");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let file_name = e.file_name();
        let Some(pid) = file_name
            .to_str()
            .and_then(|f| f.strip_prefix(&prefix))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        let alive = Path::new("/proc").join(pid.to_string()).exists();
        if !alive && e.file_type().is_ok_and(|t| t.is_file()) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Half-written table files of `path` by `pids`, and one of another table's.
    fn partials(path: &Path, pids: &[u32]) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = pids.iter().map(|&p| partial_path(path, p)).collect();
        files.push(path.with_file_name("other.vis.partial-4194305"));
        for p in &files {
            std::fs::write(p, b"half a table").unwrap();
        }
        files
    }

    /// A table file left half written by a process that was killed is removed; one of a process
    /// that still runs (pid 1 always does) is not, nor another table's. 4194305 is above Linux's
    /// largest pid (2^22): no process has it.
    #[test]
    fn stale_partial_files_are_those_of_dead_processes_only() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.vis");
        let files = partials(&path, &[4_194_305, 1]);
        remove_stale_partials(&path);
        assert!(!files[0].exists(), "the dead writer's file is removed");
        assert!(files[1].exists() && files[2].exists());
    }

    /// ... and a save clears them, leaving no file of its own beside the table.
    #[cfg(feature = "build")]
    #[test]
    fn a_save_removes_the_partial_files_of_dead_processes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.vis");
        let files = partials(&path, &[4_194_305, 1]);
        // A box room 4 × 3 × 2.5 m.
        let obj = "v 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nv 0 0 2.5\nv 4 0 2.5\nv 4 3 2.5\nv 0 3 2.5\n\
                   f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n";
        let model = omnitrack_core::model::Model::from_obj_str(obj, "room.obj").expect("a valid model");
        let table = crate::visibility::build::build_table(&model, "room.obj", &Default::default());
        table.save(&path).unwrap();
        assert!(VisibilityTable::load_unchecked(&path).is_ok());
        assert!(!files[0].exists(), "the dead writer's file is removed");
        assert!(files[1].exists() && files[2].exists());
        assert!(
            !partial_path(&path, std::process::id()).exists(),
            "its own is renamed into place"
        );
    }

    #[test]
    fn delta_round_trip() {
        let ids = vec![0, 1, 5, 6, 1000, 70000];
        let mut out = Vec::new();
        delta_decode(&delta_encode(&ids), &mut out).unwrap();
        assert_eq!(out, ids);
    }
}
