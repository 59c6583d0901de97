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
//!
//! Files: this one holds the table in memory and its O(1) query; module `file` the file format
//! and the model hash; module `query` the `visibility query` command's JSON; [`build`] the
//! desk-only builder.

pub mod at_pose;
#[cfg(feature = "build")]
pub mod build;
mod file;
mod query;

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

pub use file::{model_hash, segment_vertex_ids, RawTable, FORMAT_VERSION, MAGIC};
pub use query::{parse_point, query_json, run_query, PointError};

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

impl VisibilityTable {
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
