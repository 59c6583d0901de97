//! The prior visibility table VIS(T) of Koch & Teller 2007 §4.3.
//!
//! In: a building [`Model`] and the `[visibility]` section of the tracker config. Out: a table
//! that maps any 3D position T to the visibility set (faces, segments, vertices) of the node
//! that serves it, in O(1) and without allocation ([`VisibilityTable::query`]).
//!
//! **Nodes** (§4.1.1) lie on a grid over the model's bounding box: in x and y at the centres of
//! `node_spacing_m` cells, in z at `node_heights_m` above the lowest point of the model (the
//! ground floor; one storey). Each node's cell is its Voronoi region on that grid. A node is
//! *valid* (a camera can be there) when it is in free space inside the building — see
//! [`build`] for the exact rule; in short: the floor below and the ceiling above are hit from
//! their visible side, at least half of 26 rays hit a face, at most a tenth of the hits see a
//! face from behind (which is what a point inside a wall, a pillar or a slab sees), and no face
//! is nearer than 0.2 m. Rays that leave through an open door or window count as misses, which
//! are allowed, so rooms with openings keep their nodes; a point outside the building has no
//! floor below it.
//!
//! **Lookup**: every node cell is split into 4 × 4 lookup cells in x, y; each lookup cell stores
//! the nearest valid node in line of sight of its centre (else the nearest valid node), so a
//! position next to a wall, whose own node is in the wall, is served from its side of the wall.
//! Query = three divisions, a scan of the (few) layer heights and two array reads.
//!
//! **Visibility sets** (§4.3, Figure 9) are computed by the desk-only builder
//! ([`build::build_table`]) with an exact software cube-map rasteriser: face ids and depth per
//! pixel; visible faces = ids in the buffer; a segment is visible when at least
//! `min_visible_pixels` of its rasterised pixels pass the depth test against the full model
//! (ambiguous pixels — silhouettes, grazing surfaces — are settled by an exact ray);
//! vertices = end points of visible segments. Geometry farther than `max_range_m` (40 m) from a
//! node is not rendered.
//!
//! **File**: 8 magic bytes `OMNIVIS\n`, then a postcard [`TableHeader`] (format version, FNV-1a
//! hash of the model, model path, grid, spacing, heights, build settings), then the postcard
//! body: per lookup cell its serving node, per node its set index, per segment its end-point
//! vertex ids, and the deduplicated sets as delta-coded sorted id lists (vertex lists are
//! derived on load), then 8 bytes of FNV-1a checksum over everything before them. Loading
//! against a different model, or a damaged file, is an error that says so. The header records
//! every `[visibility]` setting the table was built with ([`TableHeader::differs_from`]), so a
//! cached table built with other settings is rebuilt, not reused.
//!
//! **At the pose** ([`at_pose`], beyond the paper): the node's set refined by ray casting from
//! the position itself, for scoring where the nearest node stands in another room.

pub mod at_pose;
#[cfg(feature = "build")]
pub mod build;

/// Most grid cells a table may have: a 10⁵ m² campus at the default 1 m spacing and three
/// heights is 3·10⁵; this is 100 times that, about a gigabyte of node sets at most.
pub const MAX_GRID_CELLS: u64 = 30_000_000;

/// The node grid over a model's bounds at `spacing_m` with `layers` node heights: the origin of
/// its first node (x, y; z the model's lowest point) and its size in nodes.
pub(crate) fn grid(model: &Model, spacing_m: f64, layers: usize) -> ([f64; 3], [u32; 3]) {
    let (lo, hi) = model.bounds().unwrap_or((Point3::origin(), Point3::origin()));
    let s = spacing_m;
    // Saturating: a grid too large to count is refused by `check_grid`, never wrapped.
    let n = |a: f64, b: f64| (((b - a) / s).ceil().clamp(1.0, f64::from(u32::MAX))) as u32;
    let (nx, ny) = (n(lo.x, hi.x), n(lo.y, hi.y));
    // Centre the nodes: the grid spans (n·s) around the bounds' centre.
    let ox = 0.5 * (lo.x + hi.x) - 0.5 * (nx as f64 - 1.0) * s;
    let oy = 0.5 * (lo.y + hi.y) - 0.5 * (ny as f64 - 1.0) * s;
    ([ox, oy, lo.z], [nx, ny, layers as u32])
}

/// Whether `model`'s table at `spacing_m` with `layers` heights is small enough to build (at
/// most [`MAX_GRID_CELLS`]), checked before a byte of it is allocated (by the build, `run`'s own
/// build and `check`); the message says how to fix it.
pub fn check_grid(model: &Model, spacing_m: f64, layers: usize) -> Result<(), String> {
    let (_, [nx, ny, nz]) = grid(model, spacing_m, layers);
    let cells = u64::from(nx) * u64::from(ny) * u64::from(nz);
    if cells <= MAX_GRID_CELLS {
        return Ok(());
    }
    let (lo, hi) = model.bounds().unwrap_or((Point3::origin(), Point3::origin()));
    Err(format!(
        "a {:.0} m × {:.0} m model at {spacing_m} m node spacing is {cells} grid cells, more than {MAX_GRID_CELLS}: \
         use a wider spacing ([visibility] node_spacing_m, --spacing-m) or one building per model",
        hi.x - lo.x,
        hi.y - lo.y,
    ))
}

use nalgebra::Point3;
use omnitrack_core::model::Model;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Bumped whenever the file layout changes.
pub const FORMAT_VERSION: u32 = 2;
/// First bytes of every table file.
pub const MAGIC: [u8; 8] = *b"OMNIVIS\n";
/// `cell_node` entry of a cell with no valid node anywhere.
pub const NO_NODE: u32 = u32::MAX;

/// What goes wrong with a table; every message is one line naming the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VisibilityError {
    #[error("{file}: cannot {action}: {message}")]
    Io {
        file: String,
        action: &'static str,
        message: String,
    },
    #[error("{file}: not an omnitrack visibility table ({message})")]
    Format { file: String, message: String },
    #[error("{file}: visibility table format version {found}, this omnitrack reads version {expected}; rebuild it with `omnitrack visibility build`")]
    Version { file: String, found: u32, expected: u32 },
    #[error("{file}: visibility table was built for a different model (model hash {table_hash:016x}, {model} has hash {model_hash:016x}); rebuild it with `omnitrack visibility build`")]
    ModelMismatch {
        file: String,
        model: String,
        table_hash: u64,
        model_hash: u64,
    },
    #[error("{file}: {message}")]
    Invalid { file: String, message: String },
}

/// The table's header: what it was built from and how.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableHeader {
    pub format_version: u32,
    /// [`model_hash`] of the model the table was built for.
    pub model_hash: u64,
    /// The model file given to `build` (absolute when it could be resolved); `query` reads it.
    pub model_path: String,
    pub vertex_count: u32,
    pub face_count: u32,
    pub segment_count: u32,
    /// World position of grid node (0, 0, layer 0) without the layer height: x, y of the first
    /// node and the floor z to which `heights_m` are added.
    pub origin: [f64; 3],
    /// Grid cells in x, y and layers.
    pub dims: [u32; 3],
    pub spacing_m: f64,
    /// Layer heights above `origin[2]`, ascending.
    pub heights_m: Vec<f64>,
    pub cube_map_resolution: u32,
    pub min_visible_pixels: u32,
    /// Triangles farther than this from a node were not rendered.
    pub max_range_m: f64,
    /// How each node's set was widened to its cell: 0 the node alone, 1 union with its
    /// line-of-sight grid neighbours, 2 union with renders at its cell's corners.
    pub merge: u8,
    /// Valid nodes.
    pub node_count: u32,
    /// The query lookup grid splits every node cell into `lookup_subdivisions²` cells in x, y,
    /// each served by the nearest valid node in line of sight of its centre (so that a position
    /// near a wall is not served by a node on the other side).
    pub lookup_subdivisions: u32,
    /// Minimum distance from a valid node to any face (version 2).
    pub clearance_m: f64,
    /// Segments shorter than this entered no set (version 2).
    pub min_segment_length_m: f64,
}

impl TableHeader {
    /// The first `[visibility]` setting of `c` that this table was not built with, as
    /// `name: table value, config value`; `None` when the table is what `c` would build.
    pub fn differs_from(&self, c: &omnitrack_config::VisibilityConfig) -> Option<String> {
        let mut heights = c.node_heights_m.clone();
        heights.sort_by(f64::total_cmp);
        if self.spacing_m != c.node_spacing_m {
            return Some(format!(
                "node_spacing_m: table {}, config {}",
                self.spacing_m, c.node_spacing_m
            ));
        }
        if self.heights_m != heights {
            return Some(format!(
                "node_heights_m: table {:?}, config {:?}",
                self.heights_m, heights
            ));
        }
        if self.cube_map_resolution != c.cube_map_resolution {
            return Some(format!(
                "cube_map_resolution: table {}, config {}",
                self.cube_map_resolution, c.cube_map_resolution
            ));
        }
        if self.min_visible_pixels != c.min_visible_pixels {
            return Some(format!(
                "min_visible_pixels: table {}, config {}",
                self.min_visible_pixels, c.min_visible_pixels
            ));
        }
        if self.min_segment_length_m != c.min_segment_length_m {
            return Some(format!(
                "min_segment_length_m: table {}, config {}",
                self.min_segment_length_m, c.min_segment_length_m
            ));
        }
        None
    }
}

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

/// One node's visibility set, borrowed from the table (no allocation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisibilitySet<'a> {
    /// Index of the node among the table's valid nodes.
    pub node: u32,
    pub node_position: Point3<f64>,
    /// Indices into `Model::faces`, ascending.
    pub faces: &'a [u32],
    /// Indices into `Model::segments`, ascending.
    pub segments: &'a [u32],
    /// Indices into `Model::vertices`, ascending.
    pub vertices: &'a [u32],
}

/// The loaded table: flat arrays, queried in O(1).
#[derive(Debug, Clone, PartialEq)]
pub struct VisibilityTable {
    pub header: TableHeader,
    cell_node: Vec<u32>,
    node_cell: Vec<u32>,
    node_set: Vec<u32>,
    /// Per set: [faces start, segments start, vertices start] into the arrays below; the end is
    /// the next set's start (one extra entry at the end).
    set_start: Vec<[u32; 3]>,
    faces: Vec<u32>,
    segments: Vec<u32>,
    vertices: Vec<u32>,
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
        let mut temporary = path.as_os_str().to_owned();
        temporary.push(format!(".partial-{}", std::process::id()));
        let temporary = PathBuf::from(temporary);
        let written = (|| {
            let mut f = std::fs::File::create(&temporary)?;
            std::io::Write::write_all(&mut f, &self.to_bytes())?;
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

    pub fn node_count(&self) -> usize {
        self.node_cell.len()
    }

    /// Distinct visibility sets stored.
    pub fn set_count(&self) -> usize {
        self.set_start.len() - 1
    }

    /// World position of a grid cell's node.
    pub fn cell_position(&self, cell: usize) -> Point3<f64> {
        let h = &self.header;
        let (nx, ny) = (h.dims[0] as usize, h.dims[1] as usize);
        let (i, j, k) = (cell % nx, (cell / nx) % ny, cell / (nx * ny));
        Point3::new(
            h.origin[0] + i as f64 * h.spacing_m,
            h.origin[1] + j as f64 * h.spacing_m,
            h.origin[2] + h.heights_m[k],
        )
    }

    /// World position of valid node `node`.
    pub fn node_position(&self, node: u32) -> Point3<f64> {
        self.cell_position(self.node_cell[node as usize] as usize)
    }

    /// The lookup cell that contains `at` (positions outside the grid are clamped to it).
    pub fn lookup_cell_of(&self, at: &Point3<f64>) -> usize {
        let h = &self.header;
        let m = h.lookup_subdivisions as usize;
        let step = h.spacing_m / m as f64;
        let axis = |c: f64, o: f64, n: u32| -> usize {
            let i = ((c - (o - 0.5 * h.spacing_m)) / step).floor();
            if i.is_nan() || i < 0.0 {
                0
            } else {
                (i as usize).min(n as usize * m - 1)
            }
        };
        let i = axis(at.x, h.origin[0], h.dims[0]);
        let j = axis(at.y, h.origin[1], h.dims[1]);
        let dz = at.z - h.origin[2];
        let mut k = 0;
        for (l, &height) in h.heights_m.iter().enumerate() {
            if (height - dz).abs() < (h.heights_m[k] - dz).abs() {
                k = l;
            }
        }
        let (lx, ly) = (h.dims[0] as usize * m, h.dims[1] as usize * m);
        (k * ly + j) * lx + i
    }

    /// VIS(T): the visibility set of the node serving position `at`: the nearest valid node in
    /// line of sight of the centre of the lookup cell containing `at` (usually the node of its
    /// own node cell). `None` only for a table without any valid node. O(1), no allocation.
    pub fn query(&self, at: &Point3<f64>) -> Option<VisibilitySet<'_>> {
        let node = self.cell_node[self.lookup_cell_of(at)];
        if node == NO_NODE {
            return None;
        }
        Some(self.node_set(node))
    }

    /// The visibility set of valid node `node` (< [`Self::node_count`]).
    pub fn node_set(&self, node: u32) -> VisibilitySet<'_> {
        let set = self.node_set[node as usize] as usize;
        let (a, b) = (self.set_start[set], self.set_start[set + 1]);
        VisibilitySet {
            node,
            node_position: self.node_position(node),
            faces: &self.faces[a[0] as usize..b[0] as usize],
            segments: &self.segments[a[1] as usize..b[1] as usize],
            vertices: &self.vertices[a[2] as usize..b[2] as usize],
        }
    }

    /// Total ids held in memory (faces + segments + vertices over distinct sets).
    pub fn stored_ids(&self) -> usize {
        self.faces.len() + self.segments.len() + self.vertices.len()
    }
}

fn push_num(out: &mut String, x: f64) {
    if x.is_finite() {
        // Shortest representation that reads back to the same f64; integers without ".0".
        if x == x.trunc() && x.abs() < 1e15 {
            let _ = write!(out, "{}", x as i64);
        } else {
            let _ = write!(out, "{x}");
        }
    } else {
        out.push_str("null");
    }
}

fn push_point(out: &mut String, p: &Point3<f64>) {
    out.push('[');
    push_num(out, p.x);
    out.push(',');
    push_num(out, p.y);
    out.push(',');
    push_num(out, p.z);
    out.push(']');
}

/// The JSON of `omnitrack visibility query` (docs/interfaces.md): `{"node_m":[x,y,z],"faces":[OBJ
/// face numbers],"segments":[[x1,y1,z1,x2,y2,z2],...],"vertices":[[x,y,z],...]}` for the node
/// serving `at`. Faces are 1-based OBJ face numbers in file order (a non-planar record split
/// into several faces appears once). A table without valid nodes gives `"node_m":null` and
/// empty lists.
pub fn query_json(table: &VisibilityTable, model: &Model, at: &Point3<f64>) -> String {
    let mut out = String::from("{\"node_m\":");
    let Some(set) = table.query(at) else {
        out.push_str("null,\"faces\":[],\"segments\":[],\"vertices\":[]}");
        return out;
    };
    push_point(&mut out, &set.node_position);
    out.push_str(",\"faces\":[");
    let mut numbers: Vec<u32> = set
        .faces
        .iter()
        .filter_map(|&f| model.faces.get(f as usize).map(|f| f.obj_number))
        .collect();
    numbers.sort_unstable();
    numbers.dedup();
    for (i, n) in numbers.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        let _ = write!(out, "{n}");
    }
    out.push_str("],\"segments\":[");
    for (i, &s) in set.segments.iter().enumerate() {
        let Some(seg) = model.segments.get(s as usize) else {
            continue;
        };
        if i > 0 {
            out.push(',');
        }
        out.push('[');
        for (k, c) in [seg.a.x, seg.a.y, seg.a.z, seg.b.x, seg.b.y, seg.b.z]
            .into_iter()
            .enumerate()
        {
            if k > 0 {
                out.push(',');
            }
            push_num(&mut out, c);
        }
        out.push(']');
    }
    out.push_str("],\"vertices\":[");
    for (i, &v) in set.vertices.iter().enumerate() {
        let Some(p) = model.vertices.get(v as usize) else {
            continue;
        };
        if i > 0 {
            out.push(',');
        }
        push_point(&mut out, p);
    }
    out.push_str("]}");
    out
}

/// Parses `x,y,z` (negative numbers allowed, e.g. `-1.5,2,1.6`).
pub fn parse_point(text: &str) -> Result<Point3<f64>, PointError> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(PointError::NotThree(text.to_string()));
    }
    let mut c = [0.0; 3];
    for (k, p) in parts.iter().enumerate() {
        c[k] = p
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| PointError::NotANumber {
                text: text.to_string(),
                part: p.to_string(),
            })?;
    }
    Ok(Point3::new(c[0], c[1], c[2]))
}

/// Why `--at` is not a position.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PointError {
    #[error("--at {0:?}: expected x,y,z (three numbers separated by commas)")]
    NotThree(String),
    #[error("--at {text:?}: {part:?} is not a number")]
    NotANumber { text: String, part: String },
}

/// `omnitrack visibility query --visibility V --at x,y,z`: reads the table, reads the model it
/// was built from (the path recorded in its header), checks the model hash and returns the JSON
/// line of [`query_json`].
pub fn run_query(visibility: &Path, at: &Point3<f64>) -> Result<String, VisibilityError> {
    let table = VisibilityTable::load_unchecked(visibility)?;
    let file = visibility.display().to_string();
    let model_path = PathBuf::from(&table.header.model_path);
    let model = Model::load(&model_path).map_err(|e| VisibilityError::Invalid {
        file: file.clone(),
        message: format!("cannot read the model the table was built from: {e}"),
    })?;
    table.check_model(&model, &file, &model_path.display().to_string())?;
    Ok(query_json(&table, &model, at))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delta_round_trip() {
        let ids = vec![0, 1, 5, 6, 1000, 70000];
        let mut out = Vec::new();
        delta_decode(&delta_encode(&ids), &mut out).unwrap();
        assert_eq!(out, ids);
    }

    #[test]
    fn parse_point_accepts_negative() {
        assert_eq!(parse_point("-1.5,2,1.6").unwrap(), Point3::new(-1.5, 2.0, 1.6));
        assert!(parse_point("1,2").is_err());
        assert!(parse_point("1,x,2").is_err());
    }
}
