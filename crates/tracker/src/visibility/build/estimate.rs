//! What a visibility build will hold at its peak, known before a byte of its table is allocated.
//!
//! In: the model and the build's options (and, for the check, the memory the machine has free).
//! Out: a [`BuildEstimate`] (grid cells, expected nodes, ids per node, peak bytes), or one line
//! refusing the build, with the estimate, what is free and a spacing that would fit.
//!
//! Why: a build's memory follows the grid (`cells`), the valid nodes and how much each node sees,
//! and a model can be anything the OBJ rules allow: a 3 km × 3 km site at the shipped 1 m spacing
//! passed the grid-size check and its build aborted out of memory at 1.7 GB after 88 s (issue 50).
//! The grid is known from the bounds; the rest is sampled: the node rule on cells spread evenly
//! over the grid, and the node's own render (with its merge renders, when merging) on a few of
//! the valid ones. The sums below follow the build's own buffers (`build_raw`, then the packing
//! of `VisibilityTable::from_raw`, then the serialised file image `save` writes), so the estimate
//! is an upper bound of the same shape, not a constant fitted to one model
//! (`tests/visibility_memory.rs` holds it between the measured peak and 2.5 times it).

use super::{grid, BuildOptions, CubeMap, Merge, Occluders, LOOKUP_SUBDIVISIONS};
use nalgebra::{Point3, Vector3};
use omnitrack_core::model::Model;

/// Cells tested with the node rule (spread evenly over the grid).
const SAMPLE_CELLS: usize = 2048;
/// Valid sampled nodes rendered for their visible sets.
const SAMPLE_NODES: usize = 16;
/// A `Vec` of ids as the build holds it: its header, and the allocator's own bookkeeping.
const VEC_BYTES: f64 = 24.0 + 16.0;

/// A build's size before it starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuildEstimate {
    /// Grid cells (nodes × layers before the node rule).
    pub cells: u64,
    /// Valid nodes expected (the sampled share of the cells).
    pub nodes: u64,
    /// Face and segment ids per node, as the merged sets hold them.
    pub ids_per_node: f64,
    /// Bytes the build holds at its peak.
    pub peak_bytes: u64,
}

/// Estimates a build of `model` with `opts`: the grid from the bounds, the node share and the
/// set sizes from samples (see the module doc). Costs the node rule on 2,048 cells and up to 16
/// renders (five times as many when merging with the cell corners).
pub fn estimate(model: &Model, opts: &BuildOptions) -> BuildEstimate {
    let (origin, [nx, ny, nz]) = grid(model, opts);
    let (nx, ny, nz) = (u64::from(nx), u64::from(ny), u64::from(nz));
    let cells = nx * ny * nz;
    let mut heights = opts.heights_m.clone();
    heights.sort_by(f64::total_cmp);
    let pos = |c: u64| {
        let (i, j, k) = (c % nx, (c / nx) % ny, c / (nx * ny));
        Point3::new(
            origin[0] + i as f64 * opts.spacing_m,
            origin[1] + j as f64 * opts.spacing_m,
            origin[2] + heights[k as usize],
        )
    };
    let scene = Occluders::new(model);
    let samples = (SAMPLE_CELLS as u64).min(cells).max(1);
    // A stride coprime with nothing in particular: evenly over the cells, not one grid column.
    let sampled: Vec<u64> = (0..samples).map(|s| (s * cells + cells / 2) / samples).collect();
    let valid: Vec<u64> = sampled
        .iter()
        .copied()
        .filter(|&c| scene.is_free(&pos(c), opts.clearance_m))
        .collect();
    let nodes = (cells as f64 * valid.len() as f64 / samples as f64).ceil() as u64;

    let res = opts.cube_map_resolution as usize;
    let mut cube = CubeMap::new(res, model.faces.len());
    let step = (valid.len() / SAMPLE_NODES).max(1);
    let (mut own_ids, mut merged_ids, mut rendered) = (0usize, 0usize, 0usize);
    for &c in valid.iter().step_by(step).take(SAMPLE_NODES) {
        let here = pos(c);
        let (mut f, mut s) = cube.visibility(&scene, &here, opts);
        own_ids += f.len() + s.len();
        let half = 0.5 * opts.spacing_m;
        let around: Vec<Vector3<f64>> = match opts.merge {
            Merge::None => Vec::new(),
            Merge::CellCorners => [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)]
                .map(|(a, b)| Vector3::new(a * half, b * half, 0.0))
                .to_vec(),
            Merge::Neighbours => [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)]
                .map(|(a, b)| Vector3::new(a * opts.spacing_m, b * opts.spacing_m, 0.0))
                .to_vec(),
        };
        // Every merge render that could join the set, line of sight or not: an upper bound.
        for d in around {
            let p = here + d;
            if scene.is_free(&p, opts.clearance_m) {
                let (cf, cs) = cube.visibility(&scene, &p, opts);
                f.extend(cf);
                s.extend(cs);
            }
        }
        f.sort_unstable();
        f.dedup();
        s.sort_unstable();
        s.dedup();
        merged_ids += f.len() + s.len();
        rendered += 1;
    }
    let per_node = |ids: usize| {
        if rendered == 0 {
            0.0
        } else {
            ids as f64 / rendered as f64
        }
    };
    let (own, merged) = (per_node(own_ids), per_node(merged_ids));
    // Held while the nodes render: the scene, and a cube map per thread of the pool.
    let renderers = scene.heap_bytes() as f64 + rayon::current_num_threads() as f64 * cube.heap_bytes() as f64;

    let m2 = (LOOKUP_SUBDIVISIONS * LOOKUP_SUBDIVISIONS) as f64;
    let (c, n) = (cells as f64, nodes as f64);
    // The nodes' own sets (faces and segments, two Vecs each), and the renders they come from as
    // (faces, segments) pairs, split into the two lists (48 B a node each, both held a moment).
    let sets = n * (2.0 * VEC_BYTES + 4.0 * own);
    let pairs = n * 96.0;
    // Nodes: validity (1 B a cell), cell → node (4 B), node → cell (4 B a node).
    let grid_bytes = c * 5.0 + n * 4.0;
    let lookup = c * m2 * 4.0;
    // A merged set is a copy of the node's own, extended by each merge render's set before the
    // duplicates go: its capacity, which deduplication does not give back, reaches up to twice
    // the ids of all of them (4 corner renders, or 6 neighbours).
    let merge_renders = match opts.merge {
        Merge::None => 0.0,
        Merge::CellCorners => 4.0,
        Merge::Neighbours => 6.0,
    };
    let merged_sets = n * (2.0 * VEC_BYTES + 4.0 * 2.0 * (1.0 + merge_renders) * own);
    let merging = match opts.merge {
        Merge::None => 0.0,
        Merge::Neighbours => merged_sets + pairs,
        Merge::CellCorners => {
            // The corners' renders (as many as the cells' corners with a node) and their
            // indexes (22 B a corner of the grid).
            let corners = ((nx + 1) * (ny + 1) * nz) as f64;
            let rendered_corners = n * corners / c;
            merged_sets + pairs + rendered_corners * (2.0 * VEC_BYTES + 4.0 * own + 16.0) + corners * 22.0
        }
    };
    let kept = if opts.merge == Merge::None { sets } else { merged_sets };
    let building = renderers + grid_bytes + sets + pairs + merging;
    let lookups = renderers + grid_bytes + kept + lookup;
    // Packing: every set distinct at worst (a hash entry of two slices and an id, 48 B with its
    // share of empty slots; two delta-coded Vecs of at most 2 B an id), then the file image
    // `save` serialises before writing (the lookup, the node arrays and the packed sets).
    let ids = if opts.merge == Merge::None { own } else { merged };
    let packed = n * (4.0 + 48.0 + 2.0 * VEC_BYTES + 2.0 * ids);
    let image = lookup + n * 8.0 + n * 2.0 * ids;
    let packing = lookup + n * 4.0 + kept + packed + image;
    // What is not itemised (the allocator's rounding, the thread pool's job lists, the progress
    // bar, the header): a tenth more, and 64 KiB.
    let peak_bytes = (1.1 * building.max(lookups).max(packing) + 65536.0).ceil() as u64;
    let ids_per_node = ids;
    BuildEstimate {
        cells,
        nodes,
        ids_per_node,
        peak_bytes,
    }
}

/// Bytes the machine can give a new allocation now (`MemAvailable` of `/proc/meminfo`), if it
/// says.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Refuses a build whose estimate exceeds `available` bytes, in one line saying what it would take,
/// what is free and a node spacing that would fit (memory falls with the square of the spacing).
pub fn check_memory(model: &Model, opts: &BuildOptions, available: Option<u64>) -> Result<BuildEstimate, String> {
    let estimate = estimate(model, opts);
    let Some(available) = available else {
        return Ok(estimate);
    };
    if estimate.peak_bytes <= available {
        return Ok(estimate);
    }
    let ratio = (estimate.peak_bytes as f64 / available as f64).sqrt();
    let fits = (opts.spacing_m * ratio * 4.0).ceil() / 4.0;
    Err(format!(
        "building its visibility table at {} m node spacing would take about {:.1} GB ({} grid cells, about {} nodes \
         seeing {:.0} faces and segments each), more than the {:.1} GB this machine has free: use a spacing of \
         {fits} m or more ([visibility] node_spacing_m, --spacing-m), or one building per model",
        opts.spacing_m,
        estimate.peak_bytes as f64 / 1e9,
        estimate.cells,
        estimate.nodes,
        estimate.ids_per_node,
        available as f64 / 1e9,
    ))
}
