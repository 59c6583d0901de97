//! Building the visibility table on the CPU (desk only): node validity, an exact software
//! cube-map rasteriser (face ids + perspective-correct depth) per node, Koch–Teller's segment
//! rule (Figure 9), optional merging with neighbour nodes, parallel over nodes with rayon.
//!
//! **Valid nodes** (free space inside the building, where a person could stand). From the
//! node, 26 rays (the directions of a 3×3×3 stencil) are cast against the model. The node is
//! valid when
//! 1. the ray straight down meets a face (something to stand on);
//! 2. at least 13 of the 26 rays meet a face (the others may leave through open doors and
//!    windows, so rooms with openings keep their nodes, while a point outside the building
//!    loses them: most rays escape);
//! 3. along each horizontal axis of the stencil the faces on either side are at least
//!    0.5 m apart and along one of them at least 1.2 m, and the faces below and above at
//!    least 1.2 m (the inside of a wall, a slab or a pillar is smaller than any room; a closed
//!    box 1.2 m or more across is a room, since winding cannot say it is solid);
//! 4. no face is nearer than `clearance_m` (exact point–triangle distance; default 0.2 m).
//!
//! Nothing reads the faces' winding (docs/interfaces.md, "Building model", gives it no
//! meaning): a wall may be one face seen from both sides, faces may be duplicated or overlap,
//! and a model may have no faces outside its rooms. The rule before this one counted the faces seen "from behind",
//! and kept 459 of 1,872 nodes of a building drawn with single-face walls wound either way
//! (issue 20).
//!
//! **Per valid node**: all triangles whose bounding box comes within `max_range_m` are
//! rasterised into six `res × res` cube faces (pixel centres, 1/z interpolated linearly in
//! screen space, near-plane clipping), nearest first, skipping a triangle strictly behind the
//! farthest depth drawn in every 8 × 8 block it covers; of equal depths the smaller face id
//! wins, so the buffers are those of drawing in file order. Visible faces are the ids left in
//! the buffers. Every
//! segment within range is a candidate (the paper takes only segments bounding a visible face;
//! that misses segments whose faces cover no pixel centre: door jambs far down a corridor, the
//! outer edge of a window seen through it). A candidate is rasterised per cube face (clipped to
//! the face's frustum, one sample per pixel along its major axis). A sample passes when the
//! segment is not farther than the surface at its pixel (relative tolerance 1e-3), or when one
//! of the segment's own faces shows at that pixel or a neighbour (the segment lies on its
//! faces' borders, half a pixel from the nearest pixel centre); it fails when the segment is
//! behind every surface of the 3×3 neighbourhood; otherwise (a silhouette or a grazing surface
//! within a pixel) an exact ray from the node to the segment's point decides. A segment with at
//! least `min_visible_pixels` passing pixels is visible (the paper's rule is 2).
//!
//! **Merging** ([`Merge`]): optional union with line-of-sight grid neighbours or with renders at
//! the cell's corners. Measured on `corridor` (benches/visibility.rs), it raises the recall of
//! segments > 2° at random positions from 97.2 % to 99.6 % but lowers precision from 88 % to
//! 73 %; the default is the paper's (none).

use super::{segment_vertex_ids, RawTable, TableHeader, VisibilityTable, FORMAT_VERSION, NO_NODE};
use nalgebra::Point3;
use omnitrack_config::VisibilityConfig;
use omnitrack_core::model::Model;
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

mod cubemap;
mod estimate;
mod occluders;

pub use cubemap::CubeMap;
pub use estimate::{available_memory, check_memory, estimate, BuildEstimate};
pub use occluders::Occluders;

/// How to build a table.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildOptions {
    pub spacing_m: f64,
    /// Node layers above the model's lowest point.
    pub heights_m: Vec<f64>,
    pub cube_map_resolution: u32,
    pub min_visible_pixels: u32,
    /// Triangles whose bounding box is farther than this from a node are not rendered.
    pub max_range_m: f64,
    /// Minimum distance from a valid node to any face.
    pub clearance_m: f64,
    /// How a node's set is widened to cover its cell.
    pub merge: Merge,
    /// Segments shorter than this (m) enter no set.
    pub min_segment_length_m: f64,
    /// Show a progress bar on standard error.
    pub progress: bool,
}

/// Widening a node's visibility set to its cell (the paper's sets are those of the node only
/// and "not conservative").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Merge {
    /// The node's own render only (the paper).
    None,
    /// Union with the sets of the grid neighbours (±1 in x, y and layer) in line of sight.
    Neighbours,
    /// Union with renders at the four corners of the node's cell (at the node's height; shared
    /// by the four cells that meet there). A corner that is not free space or not in line of
    /// sight of the node is replaced by the point half-way to it, if that one is.
    CellCorners,
}

impl Merge {
    pub fn code(self) -> u8 {
        match self {
            Merge::None => 0,
            Merge::Neighbours => 1,
            Merge::CellCorners => 2,
        }
    }
}

/// Lookup cells per node cell along x and y.
pub const LOOKUP_SUBDIVISIONS: usize = 4;

/// Default maximum range of the visibility render, metres.
pub const DEFAULT_MAX_RANGE_M: f64 = 40.0;

impl BuildOptions {
    pub fn from_config(c: &VisibilityConfig) -> BuildOptions {
        BuildOptions {
            spacing_m: c.node_spacing_m,
            heights_m: c.node_heights_m.clone(),
            cube_map_resolution: c.cube_map_resolution,
            min_visible_pixels: c.min_visible_pixels,
            max_range_m: DEFAULT_MAX_RANGE_M,
            clearance_m: 0.2,
            merge: Merge::None,
            min_segment_length_m: c.min_segment_length_m,
            progress: false,
        }
    }
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions::from_config(&VisibilityConfig::default())
    }
}

/// [`super::check_grid`] with a build's options.
pub fn check_grid(model: &Model, opts: &BuildOptions) -> Result<(), String> {
    super::check_grid(model, opts.spacing_m, opts.heights_m.len())
}

/// Whether a build of `model` with `opts` can run here: the grid no larger than
/// [`super::MAX_GRID_CELLS`], then its estimated peak memory no more than the machine has free
/// ([`check_memory`]). Called before a byte of the table is allocated, by `visibility build`,
/// `run`'s own build and `check`.
pub fn check_build(model: &Model, opts: &BuildOptions) -> Result<BuildEstimate, String> {
    check_grid(model, opts)?;
    check_memory(model, opts, available_memory())
}

/// The node grid over a model's bounds ([`super::grid`]).
fn grid(model: &Model, opts: &BuildOptions) -> ([f64; 3], [u32; 3]) {
    super::grid(model, opts.spacing_m, opts.heights_m.len())
}

/// Summary of a build, for logs and the benchmark.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildStats {
    pub cells: usize,
    pub nodes: usize,
    pub seconds_nodes: f64,
    pub seconds_render: f64,
    pub mean_faces: f64,
    pub mean_segments: f64,
}

/// Builds the raw per-node sets (the table before packing); `model_path` is recorded in the
/// header. Parallel over nodes on the current rayon pool.
///
/// Panics when `spacing_m` is not positive, `heights_m` is empty or the resolution is 0
/// ([`run_build`] checks these and returns errors).
pub fn build_raw(model: &Model, model_path: &str, opts: &BuildOptions) -> (RawTable, BuildStats) {
    assert!(opts.spacing_m > 0.0 && !opts.heights_m.is_empty() && opts.cube_map_resolution > 0);
    let mut heights = opts.heights_m.clone();
    heights.sort_by(f64::total_cmp);
    let opts = &BuildOptions {
        heights_m: heights.clone(),
        ..opts.clone()
    };
    let t0 = Instant::now();
    let scene = Occluders::new(model);
    let (origin, dims) = grid(model, opts);
    let (nx, ny, nz) = (dims[0] as usize, dims[1] as usize, dims[2] as usize);
    let cells = nx * ny * nz;
    let pos = |c: usize| {
        let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
        Point3::new(
            origin[0] + i as f64 * opts.spacing_m,
            origin[1] + j as f64 * opts.spacing_m,
            origin[2] + heights[k],
        )
    };
    let valid: Vec<bool> = (0..cells)
        .into_par_iter()
        .map(|c| scene.is_free(&pos(c), opts.clearance_m))
        .collect();
    let node_cell: Vec<u32> = (0..cells).filter(|&c| valid[c]).map(|c| c as u32).collect();
    let mut cell_node = vec![NO_NODE; cells];
    for (n, &c) in node_cell.iter().enumerate() {
        cell_node[c as usize] = n as u32;
    }
    let seconds_nodes = t0.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let bar = if opts.progress {
        let bar = indicatif::ProgressBar::with_draw_target(
            Some(node_cell.len() as u64),
            indicatif::ProgressDrawTarget::stderr(),
        );
        bar.set_style(
            indicatif::ProgressStyle::with_template("visibility {bar:40} {pos}/{len} nodes, {elapsed} (eta {eta})")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    } else {
        indicatif::ProgressBar::hidden()
    };
    let res = opts.cube_map_resolution as usize;
    let sets: Vec<(Vec<u32>, Vec<u32>)> = node_cell
        .par_iter()
        .map_init(
            || CubeMap::new(res, model.faces.len()),
            |cube, &c| {
                let r = cube.visibility(&scene, &pos(c as usize), opts);
                bar.inc(1);
                r
            },
        )
        .collect();
    let (mut node_faces, mut node_segments): (Vec<Vec<u32>>, Vec<Vec<u32>>) = sets.into_iter().unzip();

    if opts.merge == Merge::CellCorners {
        let (cx, cy) = (nx + 1, ny + 1);
        let corner_pos = |ci: usize| {
            let (i, j, k) = (ci % cx, (ci / cx) % cy, ci / (cx * cy));
            Point3::new(
                origin[0] + (i as f64 - 0.5) * opts.spacing_m,
                origin[1] + (j as f64 - 0.5) * opts.spacing_m,
                origin[2] + heights[k],
            )
        };
        let corners_of = |c: usize| {
            let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
            [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(a, b)| (k * cy + j + b) * cx + i + a)
        };
        let mut needed = vec![false; cx * cy * nz];
        for &c in &node_cell {
            for ci in corners_of(c as usize) {
                needed[ci] = true;
            }
        }
        let wanted: Vec<usize> = (0..needed.len()).filter(|&ci| needed[ci]).collect();
        let free: Vec<bool> = wanted
            .par_iter()
            .map(|&ci| scene.is_free(&corner_pos(ci), opts.clearance_m))
            .collect();
        let rendered: Vec<usize> = wanted
            .iter()
            .zip(&free)
            .filter(|(_, &f)| f)
            .map(|(&ci, _)| ci)
            .collect();
        bar.set_length((node_cell.len() + rendered.len()) as u64);
        let corner_sets: Vec<(Vec<u32>, Vec<u32>)> = rendered
            .par_iter()
            .map_init(
                || CubeMap::new(res, model.faces.len()),
                |cube, &ci| {
                    let r = cube.visibility(&scene, &corner_pos(ci), opts);
                    bar.inc(1);
                    r
                },
            )
            .collect();
        let mut corner_set = vec![NO_NODE; cx * cy * nz];
        for (k, &ci) in rendered.iter().enumerate() {
            corner_set[ci] = k as u32;
        }
        let merged: Vec<(Vec<u32>, Vec<u32>)> = node_cell
            .par_iter()
            .enumerate()
            .map_init(
                || CubeMap::new(res, model.faces.len()),
                |cube, (n, &c)| {
                    let here = pos(c as usize);
                    let mut f = node_faces[n].clone();
                    let mut s = node_segments[n].clone();
                    for ci in corners_of(c as usize) {
                        let corner = corner_pos(ci);
                        if corner_set[ci] != NO_NODE && scene.clear_line(&here, &corner) {
                            let (cf, cs) = &corner_sets[corner_set[ci] as usize];
                            f.extend_from_slice(cf);
                            s.extend_from_slice(cs);
                            continue;
                        }
                        let half = here + 0.5 * (corner - here);
                        if scene.is_free(&half, opts.clearance_m) && scene.clear_line(&here, &half) {
                            let (cf, cs) = cube.visibility(&scene, &half, opts);
                            f.extend(cf);
                            s.extend(cs);
                        }
                    }
                    f.sort_unstable();
                    f.dedup();
                    s.sort_unstable();
                    s.dedup();
                    (f, s)
                },
            )
            .collect();
        (node_faces, node_segments) = merged.into_iter().unzip();
    }
    if opts.merge == Merge::Neighbours {
        let merged: Vec<(Vec<u32>, Vec<u32>)> = node_cell
            .par_iter()
            .map(|&c| {
                let c = c as usize;
                let (i, j, k) = ((c % nx) as i64, ((c / nx) % ny) as i64, (c / (nx * ny)) as i64);
                let me = cell_node[c] as usize;
                let mut f = node_faces[me].clone();
                let mut s = node_segments[me].clone();
                let here = pos(c);
                for (di, dj, dk) in [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)] {
                    let (a, b, d) = (i + di, j + dj, k + dk);
                    if a < 0 || b < 0 || d < 0 || a >= nx as i64 || b >= ny as i64 || d >= nz as i64 {
                        continue;
                    }
                    let nc = (d as usize * ny + b as usize) * nx + a as usize;
                    let other = cell_node[nc];
                    if other == NO_NODE || !scene.clear_line(&here, &pos(nc)) {
                        continue;
                    }
                    f.extend_from_slice(&node_faces[other as usize]);
                    s.extend_from_slice(&node_segments[other as usize]);
                }
                f.sort_unstable();
                f.dedup();
                s.sort_unstable();
                s.dedup();
                (f, s)
            })
            .collect();
        (node_faces, node_segments) = merged.into_iter().unzip();
    }
    bar.finish_and_clear();
    let seconds_render = t1.elapsed().as_secs_f64();

    // Every lookup cell (node cells split `m × m` in x, y): the nearest valid node in line of
    // sight of its centre among the node cells within two cells; else the nearest of those; else
    // the nearest valid node (rings of growing Chebyshev radius over all layers, stopping once
    // the ring is farther than the best so far).
    let column_has_node: Vec<bool> = (0..nx * ny)
        .map(|col| (0..nz).any(|k| cell_node[k * nx * ny + col] != NO_NODE))
        .collect();
    let column_distance = chessboard_distance(&column_has_node, nx, ny);
    let m = LOOKUP_SUBDIVISIONS;
    let (lx, ly) = (nx * m, ny * m);
    let nearest: Vec<u32> = (0..lx * ly * nz)
        .into_par_iter()
        .map(|lc| {
            if node_cell.is_empty() {
                return NO_NODE;
            }
            let (li, lj, k) = (lc % lx, (lc / lx) % ly, lc / (lx * ly));
            let p = Point3::new(
                origin[0] - 0.5 * opts.spacing_m + (li as f64 + 0.5) * opts.spacing_m / m as f64,
                origin[1] - 0.5 * opts.spacing_m + (lj as f64 + 0.5) * opts.spacing_m / m as f64,
                origin[2] + heights[k],
            );
            let (i, j) = ((li / m) as i64, (lj / m) as i64);
            let mut near: Vec<(f64, u32, usize)> = Vec::new();
            for b in (j - 2)..=(j + 2) {
                for a in (i - 2)..=(i + 2) {
                    if a < 0 || b < 0 || a >= nx as i64 || b >= ny as i64 {
                        continue;
                    }
                    for kk in 0..nz {
                        let nc = (kk * ny + b as usize) * nx + a as usize;
                        if cell_node[nc] != NO_NODE {
                            near.push(((pos(nc) - p).norm_squared(), cell_node[nc], nc));
                        }
                    }
                }
            }
            near.sort_by(|x, y| x.0.total_cmp(&y.0));
            for &(_, n, nc) in &near {
                if scene.clear_line(&p, &pos(nc)) {
                    return n;
                }
            }
            if let Some(&(_, n, _)) = near.first() {
                return n;
            }
            let mut best = (f64::INFINITY, NO_NODE);
            // Rings nearer than the nearest column with a node are empty: start at it. A ring is
            // walked in the order of its bounding square (rows up, columns along), so that ties
            // go to the same node as a scan of the whole square would give them.
            let start = i64::from(column_distance[j as usize * nx + i as usize].max(1));
            for r in start..=(nx.max(ny) as i64) {
                if (r as f64 - 2.0) * opts.spacing_m > best.0.sqrt() {
                    break;
                }
                for b in (j - r)..=(j + r) {
                    if b < 0 || b >= ny as i64 {
                        continue;
                    }
                    let step = if (b - j).abs() == r { 1 } else { 2 * r };
                    for a in ((i - r)..=(i + r)).step_by(step as usize) {
                        if a < 0 || a >= nx as i64 || !column_has_node[b as usize * nx + a as usize] {
                            continue;
                        }
                        for kk in 0..nz {
                            let nc = (kk * ny + b as usize) * nx + a as usize;
                            if cell_node[nc] != NO_NODE {
                                let d2 = (pos(nc) - p).norm_squared();
                                if d2 < best.0 {
                                    best = (d2, cell_node[nc]);
                                }
                            }
                        }
                    }
                }
            }
            best.1
        })
        .collect();

    let n = node_cell.len().max(1) as f64;
    let stats = BuildStats {
        cells,
        nodes: node_cell.len(),
        seconds_nodes,
        seconds_render,
        mean_faces: node_faces.iter().map(Vec::len).sum::<usize>() as f64 / n,
        mean_segments: node_segments.iter().map(Vec::len).sum::<usize>() as f64 / n,
    };
    let header = TableHeader {
        format_version: FORMAT_VERSION,
        model_hash: super::model_hash(model),
        model_path: model_path.to_string(),
        vertex_count: model.vertices.len() as u32,
        face_count: model.faces.len() as u32,
        segment_count: model.segments.len() as u32,
        origin,
        dims,
        spacing_m: opts.spacing_m,
        heights_m: heights,
        cube_map_resolution: opts.cube_map_resolution,
        min_visible_pixels: opts.min_visible_pixels,
        max_range_m: opts.max_range_m,
        merge: opts.merge.code(),
        node_count: node_cell.len() as u32,
        lookup_subdivisions: m as u32,
        clearance_m: opts.clearance_m,
        min_segment_length_m: opts.min_segment_length_m,
    };
    let raw = RawTable {
        header,
        cell_node: nearest,
        node_cell,
        node_faces,
        node_segments,
        segment_vertices: segment_vertex_ids(model),
    };
    (raw, stats)
}

/// Per cell of an `nx × ny` grid, the chessboard (Chebyshev) distance in cells to the nearest
/// `true` cell (`u32::MAX / 2` when there is none): two chamfer passes with unit steps to all
/// eight neighbours, which is exact for this metric.
fn chessboard_distance(set: &[bool], nx: usize, ny: usize) -> Vec<u32> {
    const FAR: u32 = u32::MAX / 2;
    let mut d: Vec<u32> = set.iter().map(|&s| if s { 0 } else { FAR }).collect();
    let at = |d: &[u32], i: i64, j: i64| {
        if i < 0 || j < 0 || i >= nx as i64 || j >= ny as i64 {
            FAR
        } else {
            d[j as usize * nx + i as usize]
        }
    };
    for j in 0..ny as i64 {
        for i in 0..nx as i64 {
            let n = [
                at(&d, i - 1, j),
                at(&d, i - 1, j - 1),
                at(&d, i, j - 1),
                at(&d, i + 1, j - 1),
            ];
            let c = j as usize * nx + i as usize;
            d[c] = d[c].min(n.iter().min().map_or(FAR, |&v| v.saturating_add(1)));
        }
    }
    for j in (0..ny as i64).rev() {
        for i in (0..nx as i64).rev() {
            let n = [
                at(&d, i + 1, j),
                at(&d, i + 1, j + 1),
                at(&d, i, j + 1),
                at(&d, i - 1, j + 1),
            ];
            let c = j as usize * nx + i as usize;
            d[c] = d[c].min(n.iter().min().map_or(FAR, |&v| v.saturating_add(1)));
        }
    }
    d
}

/// Builds a packed table.
pub fn build_table(model: &Model, model_path: &str, opts: &BuildOptions) -> VisibilityTable {
    VisibilityTable::from_raw(build_raw(model, model_path, opts).0)
}

/// `omnitrack visibility build --model M --out V [--spacing-m S]`: loads the model, builds the
/// table with `config` (spacing overridden by `spacing_m`), with a progress bar on standard
/// error, and writes it. Returns the one-line summary to log.
pub fn run_build(
    model_path: &Path,
    out: &Path,
    spacing_m: Option<f64>,
    config: &VisibilityConfig,
) -> Result<String, super::VisibilityError> {
    let model = Model::load(model_path).map_err(|e| super::VisibilityError::Invalid {
        file: model_path.display().to_string(),
        message: format!("cannot use model: {}", e.message),
    })?;
    if model.faces.is_empty() {
        return Err(super::VisibilityError::Invalid {
            file: model_path.display().to_string(),
            message: "model has no faces: nothing to build a visibility table from".into(),
        });
    }
    let mut opts = BuildOptions::from_config(config);
    if let Some(s) = spacing_m {
        if !(s.is_finite() && s > 0.0) {
            return Err(super::VisibilityError::Invalid {
                file: out.display().to_string(),
                message: format!("--spacing-m {s} must be a positive number of metres"),
            });
        }
        opts.spacing_m = s;
    }
    if opts.heights_m.is_empty() || opts.cube_map_resolution == 0 {
        return Err(super::VisibilityError::Invalid {
            file: out.display().to_string(),
            message: "[visibility] needs node_heights_m and a cube_map_resolution > 0".into(),
        });
    }
    check_build(&model, &opts).map_err(|message| super::VisibilityError::Invalid {
        file: out.display().to_string(),
        message,
    })?;
    opts.progress = true;
    let recorded = std::fs::canonicalize(model_path).unwrap_or_else(|_| model_path.to_path_buf());
    let start = Instant::now();
    let (raw, stats) = build_raw(&model, &recorded.display().to_string(), &opts);
    let table = VisibilityTable::from_raw(raw);
    table.save(out)?;
    let bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    Ok(format!(
        "{}: {} valid nodes of {} grid cells, {:.0} faces and {:.0} segments visible per node on average, {} distinct sets, {:.1} MB, built in {:.1} s",
        out.display(),
        stats.nodes,
        stats.cells,
        stats.mean_faces,
        stats.mean_segments,
        table.set_count(),
        bytes as f64 / 1e6,
        start.elapsed().as_secs_f64()
    ))
}
