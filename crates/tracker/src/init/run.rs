//! The search itself ([`Initialiser::run`]): the stages of the parent module's doc in their
//! order — the vanishing directions' rotations, the grid's scan (module `grid_scan`) and its
//! climbs (module `translation`), INIT-SEGMENT-EDGE over the volume's cells (module
//! `triplets`), the polish of their best samples, the translation vote — each within what is
//! left of the work budget; and the threads that run the whole model's lanes of the scan and
//! of the triplets ([`Initialiser::on_threads`]).
//!
//! In: a frame's edges, a [`SearchVolume`], a generator. Out: the best distinct [`Candidate`]s
//! and an [`InitReport`].

use super::*;
use omnitrack_config::GridBlank;

impl Initialiser<'_> {
    /// The grid search under the rotations of the vanishing directions, INIT-SEGMENT-EDGE over
    /// the cells meeting `volume`, the polish of the best samples, and the translation vote.
    /// Returns the distinct candidates, best [`Candidate::merit`] first (empty if nothing was
    /// found).
    pub fn run(&mut self, edges: &[Edge], volume: &SearchVolume, rng: &mut SmallRng) -> (&[Candidate], InitReport) {
        let started = Instant::now();
        let limit = self.work_limit();
        let _running = self.progress.begin(limit, volume.diameter_m);
        self.work = 0;
        self.rays_charged = self.at_pose.rays_cast();
        self.backstop_hit = false;
        self.backstop = started + self.opts.time_budget.saturating_mul(self.backstop_factor);
        let mut report = InitReport::default();
        self.candidates.clear();
        self.pool.clear();
        self.prepare_edges(edges);
        self.grid_blank = match self.opts.grid_blank {
            GridBlank::Off => false,
            GridBlank::Volumes => volume.diameter_m.is_some(),
            GridBlank::Everywhere => true,
        };
        let near_radius = if self.grid_blank {
            self.opts.blank_radius_rad
        } else {
            0.0
        };
        self.near.build(edges, near_radius);
        self.spend(self.near.marks() / work::NEAR_MARKS_PER_UNIT);
        self.select_cells(volume);
        // A volume that holds no valid node (a hint outside the building, in a wall, or in a
        // part of the model with no room to stand) is widened about its centre to the nearest
        // valid nodes, and the report says so: a search of nothing would repeat forever.
        // The hint's own extent is kept beyond the gap: it says how far off the rig may be.
        let widened = match (self.cells.is_empty(), volume.diameter_m) {
            (true, Some(d)) => self.nearest_node_gap(&volume.centre).map(|gap| SearchVolume {
                centre: volume.centre,
                diameter_m: Some(2.0 * gap + d.max(self.table.header.spacing_m)),
            }),
            _ => None,
        };
        let volume = match &widened {
            Some(w) => {
                self.select_cells(w);
                report.widened_to_m = w.diameter_m;
                w
            }
            None => volume,
        };
        report.cells_in_volume = self.cells.len();
        report.diameter_m = volume.diameter_m;
        // A sweep's later searches leave the cells the earlier ones looked at (the triplets'
        // cells by the same plan distance as the grid's).
        if self.sweep_from_m > 0.0 {
            let (centre, from) = (volume.centre, self.sweep_from_m);
            let table = self.table;
            self.cells.retain(|&(_, node)| {
                let p = table.node_position(node);
                (p.x - centre.x).hypot(p.y - centre.y) >= from
            });
        }
        let mut rotations = [UnitQuaternion::identity(); MAX_ROTATIONS];
        let found = self.vanishing.rotations(edges, self.opts.max_tilt_rad, &mut rotations);
        self.vanishing_count = 0;
        for r in &rotations[..found] {
            if self.rotation_prior.is_none_or(|(p, limit)| r.angle_to(&p) <= limit) {
                self.vanishing_rot[self.vanishing_count] = *r;
                self.vanishing_count += 1;
            }
        }
        self.climbed = 0;
        // The grid search under the vanishing directions first: on real photographs it finds
        // what the triplets miss, and the triplets then have what is left of the time budget.
        let sweep = self.grid_search(edges, volume, limit);
        report.plan_cells_in_volume = sweep.in_volume;
        report.plan_cells_scanned = sweep.scanned;
        report.plan_cells_skipped = sweep.skipped;
        report.swept_to_m = sweep.next_m;
        report.scan_work = sweep.work;
        report.positions_scored = sweep.positions;
        report.climbed = self.climbed;
        report.grid_elapsed = started.elapsed();
        report.rotations = self.vanishing_count;
        // The triplets leave twice what polishing their best samples costs: a cell's sampling
        // overshoots its check.
        let reserve = 2 * POLISHED as u64 * work::POLISH;
        let sampling_limit = limit.saturating_sub(reserve);
        if self.top.len() >= 3 && !self.spent(sampling_limit) {
            // The volume's cells are dealt out to lanes in turn (the whole model's, over a
            // thousand cells without a hint, to `LANES`; a bounded volume's to `VOLUME_LANES`),
            // each lane with its share of the work left. One lane draws from `rng`; in several,
            // each cell draws from its own generator seeded from `rng` and the cell: the result
            // depends neither on the threads nor on their timing.
            let mut scratch = std::mem::take(&mut self.scratch);
            let lanes = if volume.diameter_m.is_none() {
                LANES
            } else {
                VOLUME_LANES
            };
            let lane_limit = lane_share(sampling_limit - self.work, lanes);
            let backstop = self.backstop;
            let base: u64 = if lanes > 1 { rng.random() } else { 0 };
            let me = &*self;
            let search = |first: usize, w: &mut CellScratch, mut rng: Option<&mut SmallRng>| {
                let mut done = InitReport::default();
                w.pool.clear();
                for ci in (first..me.cells.len()).step_by(lanes) {
                    if done.work >= lane_limit {
                        done.timed_out = true;
                        break;
                    }
                    if Instant::now() >= backstop || me.cancelled() {
                        done.timed_out = true;
                        done.backstop = true;
                        break;
                    }
                    let node = me.cells[ci].1;
                    let mut own = None;
                    let rng = match rng.as_deref_mut() {
                        Some(r) => r,
                        None => own.insert(SmallRng::seed_from_u64(
                            base ^ u64::from(node).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                        )),
                    };
                    done.cells_searched += 1;
                    let matches = me.score_cell(w, node);
                    done.triplet_matches += matches;
                    let (drawn, tilted) = me.sample_cell(w, node, volume, rng);
                    done.samples += drawn;
                    done.tilted += tilted;
                    let charge = work::CELL + matches / 50 * work::CELL_PER_50_MATCHES + drawn * work::CELL_PER_SAMPLE;
                    done.work += charge;
                    me.progress.add_work(charge_of_lanes(charge, lanes));
                }
                w.done = done;
            };
            if lanes > 1 {
                self.on_threads(&mut scratch[..lanes], |k, w| search(k, w, None));
            } else {
                search(0, &mut scratch[0], Some(rng));
            }
            // In lane order, so that the sums and the pool do not depend on the threads.
            let mut lanes_work = 0;
            for w in &scratch[..lanes] {
                let part = &w.done;
                report.cells_searched += part.cells_searched;
                report.triplet_matches += part.triplet_matches;
                report.samples += part.samples;
                report.tilted += part.tilted;
                report.timed_out |= part.timed_out;
                report.backstop |= part.backstop;
                lanes_work += part.work;
            }
            report.work += charge_of_lanes(lanes_work, lanes);
            for w in &scratch[..lanes] {
                for &entry in &w.pool {
                    keep_best(&mut self.pool, entry);
                }
            }
            self.scratch = scratch;
        }
        self.pool.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        self.spend(report.work);
        let mut polished = 0;
        for pi in 0..self.pool.len() {
            if polished >= POLISHED || self.spent(limit) {
                report.timed_out |= polished < POLISHED;
                break;
            }
            let start = self.pool[pi].1;
            if self.pool[..pi]
                .iter()
                .any(|p| same_pose(&p.1, &start, 2.0 * SAME_POSITION_M, 2.0 * SAME_ROTATION_RAD))
            {
                continue;
            }
            polished += 1;
            if let Some(c) = self.polish(&start, edges) {
                self.offer(c);
            }
        }
        self.candidates.sort_unstable_by(|a, b| b.merit().total_cmp(&a.merit()));
        if let Some(d) = volume.diameter_m {
            self.vote_translations(edges, &volume.centre, d, limit);
        }
        self.candidates.sort_unstable_by(|a, b| b.merit().total_cmp(&a.merit()));
        self.candidates.truncate(self.opts.candidates);
        report.elapsed = started.elapsed();
        report.work = self.work;
        report.backstop |= self.backstop_hit;
        report.timed_out |= self.work >= limit || report.backstop;
        // A search that spent its whole budget is whole even if a cancel came after it; one
        // the clock or a cancel stopped, with a cancel set now, is not to be trusted.
        report.cancelled = report.backstop && self.cancelled();
        (&self.candidates, report)
    }

    /// Runs `job(k, &mut lanes[k])` for each lane on this thread and the helpers (module
    /// `lanes`), each taking the next lane not yet taken; what a lane computes stays in it, so
    /// that nothing downstream depends on the threads.
    pub(super) fn on_threads<S: Send>(&self, lanes: &mut [S], job: impl Fn(usize, &mut S) + Sync) {
        self.helpers.run(lanes, job);
    }

    /// Adds a polished candidate, or replaces the one in its place (the same pose within
    /// [`SAME_POSITION_M`] and [`SAME_ROTATION_RAD`]) if it fits the frame better (lower
    /// truncated ξ): starts from different searches settle a few centimetres apart.
    pub(super) fn offer(&mut self, c: Candidate) {
        let same = self
            .candidates
            .iter()
            .position(|o| same_pose(&o.pose, &c.pose, SAME_POSITION_M, SAME_ROTATION_RAD));
        match same {
            Some(k) if c.score < self.candidates[k].score => self.candidates[k] = c,
            Some(_) => {}
            None if self.candidates.len() < self.candidates.capacity() => self.candidates.push(c),
            None => {}
        }
    }
}
