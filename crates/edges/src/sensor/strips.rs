//! Hue strips read only for the edges that are kept (issue 51): a piece's strip samples (where
//! along it, and which way is left) are noted when it becomes a candidate, and its pixels are read
//! only if the piece, alone or merged into a longer edge, survives selection. Most candidates
//! do not: short pieces are kept only for merging.
//!
//! In: per piece, the sample points that [`fit`](super::fit) picks; per merge, the two merged
//! candidates and whether the second one runs the other way. Out: the edge's left and right
//! [`HueAcc`], equal to the bit to what reading every piece's strips at once and adding the sums
//! at each merge gave: the same samples in the same order, the same sums in the same order
//! (a merge's node keeps the order of [`HueAcc::add`] that merging used).
//!
//! Memory: the samples and the nodes are buffers sized at start-up. When either is full the
//! strips are read at once, as before, and the candidate carries its sums itself.

use super::Workspace;
use crate::hue::{HueAcc, HueTable};

/// A candidate whose hue sums are in its own `left` and `right` (no node).
pub(super) const NO_NODE: u32 = u32::MAX;

/// How a candidate's hue sums are made.
#[derive(Debug, Clone, Copy)]
pub(super) enum HueNode {
    /// A piece's strip samples, `hue_samples[start..start + len]`, not read yet.
    Samples { start: u32, len: u32 },
    /// Sums already made (a candidate that had them when it was merged with one that did not).
    Sums(HueAcc, HueAcc),
    /// Node `a`'s sums plus node `b`'s (its left and right swapped when `swap`: it ran the other
    /// way), in that order.
    Merged { a: u32, b: u32, swap: bool },
}

/// One strip sample: the sub-pixel position on the edge and the unit step to its left side.
pub(super) type StripSample = [f32; 4];

/// Adds the strip pixels of one sample to the left and right sums: `strip_px` pixels on each
/// side from `offset` px out (nearest pixel), those inside the image.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn read_sample(
    hue: &HueTable,
    rgb: &[u8],
    w: usize,
    h: usize,
    offset: f32,
    strip_px: usize,
    s: &StripSample,
    lacc: &mut HueAcc,
    racc: &mut HueAcc,
) {
    let [px, py, dx, dy] = *s;
    for t in 0..strip_px {
        let d = offset + t as f32;
        for (sign, acc) in [(1.0f32, &mut *lacc), (-1.0, &mut *racc)] {
            // +1 keeps the value positive, so truncation rounds.
            let x = (px + sign * d * dx + 1.5) as usize;
            let y = (py + sign * d * dy + 1.5) as usize;
            if x < 1 || y < 1 || x > w || y > h {
                continue;
            }
            let i = ((y - 1) * w + x - 1) * 3;
            hue.accumulate(acc, [rgb[i], rgb[i + 1], rgb[i + 2]]);
        }
    }
}

impl Workspace {
    /// The strips of samples `samples` read now.
    fn read_samples(&self, rgb: &[u8], samples: &[StripSample]) -> (HueAcc, HueAcc) {
        let (mut l, mut r) = (HueAcc::default(), HueAcc::default());
        let offset = self.params.hue_strip_offset_px;
        for s in samples {
            read_sample(&self.hue, rgb, self.w, self.h, offset, self.strip_px, s, &mut l, &mut r);
        }
        (l, r)
    }

    /// Notes a new candidate's strip samples (the last `n` of `strip_scratch`): returns its node,
    /// or [`NO_NODE`] with the sums read at once when the buffers are full.
    pub(super) fn defer_strips(&mut self, rgb: &[u8], n: usize) -> (u32, HueAcc, HueAcc) {
        let samples = self.strip_scratch.len() - n..self.strip_scratch.len();
        let room = self.hue_samples.len() + n <= self.hue_samples.capacity()
            && self.hue_nodes.len() < self.hue_nodes.capacity();
        if !self.params.hue_for_kept_only || !room {
            let (l, r) = self.read_samples(rgb, &self.strip_scratch[samples]);
            return (NO_NODE, l, r);
        }
        let start = self.hue_samples.len() as u32;
        self.hue_samples.extend_from_slice(&self.strip_scratch[samples]);
        self.hue_nodes.push(HueNode::Samples { start, len: n as u32 });
        (self.hue_nodes.len() as u32 - 1, HueAcc::default(), HueAcc::default())
    }

    /// The node of candidate `a` merged with candidate `b` (`swap`: b runs the other way), or
    /// [`NO_NODE`] with the sums made now, as merging made them before.
    pub(super) fn merge_strips(
        &mut self,
        rgb: &[u8],
        a: (u32, HueAcc, HueAcc),
        b: (u32, HueAcc, HueAcc),
        swap: bool,
    ) -> (u32, HueAcc, HueAcc) {
        let needed = 1 + usize::from(a.0 == NO_NODE) + usize::from(b.0 == NO_NODE);
        if (a.0 == NO_NODE && b.0 == NO_NODE) || self.hue_nodes.len() + needed > self.hue_nodes.capacity() {
            let (mut l, mut r) = self.sums(rgb, a);
            let (bl, br) = self.sums(rgb, b);
            let (bl, br) = if swap { (br, bl) } else { (bl, br) };
            l.add(&bl);
            r.add(&br);
            return (NO_NODE, l, r);
        }
        let mut node = |x: (u32, HueAcc, HueAcc)| {
            if x.0 != NO_NODE {
                return x.0;
            }
            self.hue_nodes.push(HueNode::Sums(x.1, x.2));
            self.hue_nodes.len() as u32 - 1
        };
        let (na, nb) = (node(a), node(b));
        self.hue_nodes.push(HueNode::Merged { a: na, b: nb, swap });
        (self.hue_nodes.len() as u32 - 1, HueAcc::default(), HueAcc::default())
    }

    /// A candidate's left and right sums: its own, or its node's, the strips read now.
    pub(super) fn sums(&mut self, rgb: &[u8], x: (u32, HueAcc, HueAcc)) -> (HueAcc, HueAcc) {
        let root = x.0 as usize;
        match self.hue_nodes.get(root) {
            None => return (x.1, x.2),
            Some(&HueNode::Samples { start, len }) => {
                let (s, n) = (start as usize, len as usize);
                return self.read_samples(rgb, &self.hue_samples[s..s + n]);
            }
            Some(_) => {}
        }
        // A node's children come before it: mark the nodes under the root (this call's stamp),
        // then make their sums in increasing order.
        self.node_stamp = self.node_stamp.wrapping_add(1);
        if self.node_stamp == 0 {
            self.node_marks.fill(0);
            self.node_stamp = 1;
        }
        let stamp = self.node_stamp;
        self.node_stack.clear();
        self.node_stack.push(x.0);
        let mut lowest = root;
        while let Some(k) = self.node_stack.pop() {
            let k = k as usize;
            lowest = lowest.min(k);
            self.node_marks[k] = stamp;
            if let HueNode::Merged { a, b, .. } = self.hue_nodes[k] {
                self.node_stack.push(a);
                self.node_stack.push(b);
            }
        }
        for k in lowest..=root {
            if self.node_marks[k] != stamp {
                continue;
            }
            self.node_sums[k] = match self.hue_nodes[k] {
                HueNode::Samples { start, len } => {
                    let (s, n) = (start as usize, len as usize);
                    self.read_samples(rgb, &self.hue_samples[s..s + n])
                }
                HueNode::Sums(l, r) => (l, r),
                HueNode::Merged { a, b, swap } => {
                    let (mut l, mut r) = self.node_sums[a as usize];
                    let (bl, br) = self.node_sums[b as usize];
                    let (bl, br) = if swap { (br, bl) } else { (bl, br) };
                    l.add(&bl);
                    r.add(&br);
                    (l, r)
                }
            };
        }
        self.node_sums[root]
    }
}
