//! Warm tree queries resume from the previous search's cut: every kept node pair's lower bound
//! less the motion since ([`Motion`]) still decides most pairs without touching the trees, and a
//! far group of pairs ([`FarPairs`]) is checked as one while the motion uses up its margin. At
//! the end of a search the cut is folded into the next warm start.

use super::bounds::Motion;
use super::{Entry, Search};
use crate::tree::warm::{Cut, CutPair, FarPairs, TreeWarmStart};
use crate::tree::BodyTree;
use sublevel_core::math::{Real, Vector3};

impl<'t, A: BodyTree + ?Sized, B: BodyTree + ?Sized> Search<'t, A, B> {
    /// Starts from the previous search's cut instead of the root pair, when the warm start has one
    /// for these trees: each pair's bound less the motion since ([`CutPair`]) is kept when it still
    /// reaches the threshold; else the pair's cheap bounds are evaluated again (along its axis,
    /// then [`CheapBounds::gap_axis`](super::CheapBounds::gap_axis)), and the pairs still below the
    /// threshold are queued. Returns false without a usable cut.
    pub(super) fn resume(&mut self) -> bool {
        let Some(cut) = self.old.and_then(|w| w.cut.as_ref()) else { return false };
        if cut.nodes != (self.a.node_count(), self.b.node_count()) {
            return false;
        }
        if self.threshold() <= 0.0 && !self.decided() {
            // Overlap within the tolerance: every bound (≥ 0) decides; the root pair covers all.
            self.pruned_min = self.pruned_min.min(0.0);
            self.keep(self.a.root(), self.b.root(), 0.0, Vector3::zeros());
            return true;
        }
        let motion = Motion::new(&self.cheap, &cut.pose);
        let (nodes_a, nodes_b) = cut.nodes;
        // Constant during the loops: the upper bound only changes when a leaf pair is solved.
        let (threshold, decided) = (self.threshold(), self.decided());
        let seeded = self.seeded.map_or((usize::MAX, usize::MAX), |s| s);
        let valid = |p: &CutPair| {
            (p.a as usize) < nodes_a && (p.b as usize) < nodes_b && (p.a as usize, p.b as usize) != seeded
        };
        // The shared pairs: only their bounds are written.
        self.base_lower.reserve_exact(cut.base.len());
        for (p, &lower) in cut.base.iter().zip(&cut.lower) {
            if lower.is_nan() || !valid(p) {
                self.base_lower.push(Real::NAN);
                continue;
            }
            let bound = motion.moved(p, lower);
            if bound >= threshold || decided {
                self.base_lower.push(bound);
                self.sphere_pruned += 1;
                self.pruned_min = self.pruned_min.min(bound);
            } else {
                self.base_lower.push(Real::NAN);
                self.revisit(CutPair { lower: bound, ..*p }, threshold);
            }
        }
        self.base = Some(cut.base.clone());
        for p in &cut.extra {
            if !valid(p) {
                continue;
            }
            let bound = motion.moved(p, p.lower);
            if bound >= threshold || decided {
                self.carry(CutPair { lower: bound, ..*p });
            } else {
                self.revisit(CutPair { lower: bound, ..*p }, threshold);
            }
        }
        if let Some((c, h)) = self.b.node_box(self.b.root()) {
            self.step = self.cheap.displacement(&cut.pose, c.norm() + h.norm());
        }
        if let Some(far) = cut.far.as_ref() {
            // The group's pairs in increasing order of bound: release those whose bound less the
            // motion since the group's pose no longer decides them; the rest stay grouped.
            let moved = self.cheap.displacement(&far.pose, far.reach);
            let mut start = cut.far_start;
            let mut motion: Option<Motion> = None;
            while start < far.pairs.len() && !decided && far.pairs[start].lower - moved < threshold {
                let p = far.pairs[start];
                start += 1;
                if !valid(&p) {
                    continue;
                }
                let bound = motion.get_or_insert_with(|| Motion::new(&self.cheap, &far.pose)).moved(&p, p.lower);
                if bound >= threshold {
                    self.carry(CutPair { lower: bound, ..p });
                } else {
                    self.revisit(CutPair { lower: bound, ..p }, threshold);
                }
            }
            if start < far.pairs.len() {
                let bound = far.pairs[start].lower - moved;
                self.sphere_pruned += far.pairs.len() - start;
                self.pruned_min = self.pruned_min.min(bound);
                self.far = Some(far.clone());
                self.far_start = start;
            }
        }
        true
    }

    /// A pair of the previous cut whose moved bound (`p.lower`) no longer decides it, evaluated
    /// again at this pose: along its axis (A's support along it is kept), then by the cheap
    /// bounds; kept when it decides, else queued. (Splitting internal pairs decided by less than a
    /// step's motion, so that their children carry more margin, cost more than re-evaluating
    /// them.)
    fn revisit(&mut self, p: CutPair, threshold: Real) {
        let (na, nb) = (p.a as usize, p.b as usize);
        let mut q = p;
        if p.axis != Vector3::zeros() {
            if p.support_a.is_nan() {
                q.support_a = self.a.support_upper(na, &p.axis).unwrap_or(Real::INFINITY);
            }
            if let Some(hb) = self.b.support_upper(nb, &-(self.cheap.rot.transpose() * p.axis)) {
                let g = p.axis.dot(&self.cheap.shift) - hb - q.support_a;
                q.lower = q.lower.max(g - self.cheap.slack * (1.0 + g.abs() + q.support_a.abs()));
            }
        }
        if q.lower.is_nan() || q.lower < 0.0 {
            // 0 bounds the distance but not the gap along the axis (it may be negative).
            q = CutPair { lower: 0.0, axis: Vector3::zeros(), support_a: Real::NAN, ..q };
        }
        if q.lower >= threshold {
            self.carry(q);
            return;
        }
        if q.axis != Vector3::zeros() && self.is_leaf_pair(na, nb) {
            // A leaf pair near the best one: the axis refined from its own, when popped, decides
            // it better than the centers' direction.
            self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
            self.heap.push(Entry { lower: q.lower, key: q.lower, axis: q.axis, a: na, b: nb });
            return;
        }
        let mut key = q.lower;
        if let Some((g, n)) = self.cheap.gap_axis(self.a, na, self.b, nb) {
            key = g;
            if g > q.lower {
                q = CutPair { lower: g, axis: n, support_a: Real::NAN, ..q };
            }
        }
        if q.lower >= threshold {
            self.carry(q);
        } else {
            self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
            self.heap.push(Entry { lower: q.lower, key, axis: q.axis, a: na, b: nb });
        }
    }

    /// Keeps a pair of the previous cut whose bound still decides it.
    #[inline]
    fn carry(&mut self, p: CutPair) {
        self.sphere_pruned += 1;
        self.pruned_min = self.pruned_min.min(p.lower);
        self.cut.push(p);
    }

    /// The state for the next query: solver warm starts, the active pair, and the cut (when not
    /// larger than [`TreeQueryParams::max_cut_pairs`](crate::tree::TreeQueryParams::max_cut_pairs)). The previous base is shared again while the pairs added
    /// since stay few and most of its pairs are still in the cut; else every pair goes to a new
    /// base.
    pub(super) fn finish(&mut self) -> TreeWarmStart {
        let mut fresh = std::mem::take(&mut self.fresh);
        let alive = self.base_lower.iter().filter(|l| !l.is_nan()).count();
        let far_len = self.far.as_ref().map_or(0, |f| f.pairs.len() - self.far_start);
        if alive + self.cut.len() + far_len > self.params.max_cut_pairs {
            return fresh;
        }
        // A new far group when there is none, or when it released more pairs than it holds.
        if self.step.is_finite() && (self.far.is_none() || self.far_start > far_len) {
            if let Some(cut) = self.regroup(fresh.active) {
                fresh.cut = Some(cut);
                return fresh;
            }
        }
        let dead = self.base_lower.len() - alive;
        let (base, lower, extra) = match self.base.take() {
            // Folding copies every pair (a few kilobytes): only when the pairs added since the
            // last fold, or the pairs gone, outnumber the kept ones.
            Some(base) if self.cut.len() <= 32 + alive && dead <= alive => {
                (base, std::mem::take(&mut self.base_lower), std::mem::take(&mut self.cut))
            }
            old => {
                let mut pairs = Vec::with_capacity(alive + self.cut.len());
                if let Some(old) = old {
                    let kept = old.iter().zip(&self.base_lower).filter(|(_, l)| !l.is_nan());
                    pairs.extend(kept.map(|(p, &l)| CutPair { lower: l, ..*p }));
                }
                pairs.append(&mut self.cut);
                let lower = pairs.iter().map(|p| p.lower).collect();
                (std::sync::Arc::new(pairs), lower, Vec::new())
            }
        };
        fresh.cut = Some(Cut {
            base,
            lower,
            extra,
            pose: self.cheap.rel,
            nodes: (self.a.node_count(), self.b.node_count()),
            far: self.far.take(),
            far_start: self.far_start,
        });
        fresh
    }

    /// The cut of the next warm start with a new far group ([`FarPairs`]): the pairs whose bound
    /// exceeds the final threshold by more than `far_steps` times this step's motion
    /// ([`TreeQueryParams::far_steps`](crate::tree::TreeQueryParams::far_steps); not the active
    /// pair, not a pair without a box), in increasing order of bound; the others near (a new
    /// base). The old far group's pairs take their bounds moved to this pose. `None` (the pairs
    /// stay as they are) when fewer than `min_far_pairs` would be far or the threshold is not
    /// finite. A search ends with most pairs just above its threshold, so about half of the cut
    /// stays near.
    fn regroup(&mut self, active: Option<(usize, usize)>) -> Option<Cut> {
        let threshold = self.threshold();
        let margin = self.params.far_steps * self.step;
        if !(threshold.is_finite() && margin.is_finite()) {
            return None;
        }
        let is_far = |p: &CutPair| {
            p.lower - threshold > margin
                && p.box_b.1.iter().all(|h| h.is_finite())
                && active != Some((p.a as usize, p.b as usize))
        };
        let old_far = self.far.as_ref().map(|f| (&f.pairs[self.far_start..], Motion::new(&self.cheap, &f.pose)));
        let kept = self.base.iter().flat_map(|b| b.iter().zip(&self.base_lower)).filter(|(_, l)| !l.is_nan());
        let pairs = kept
            .map(|(p, &l)| CutPair { lower: l, ..*p })
            .chain(self.cut.iter().copied())
            .chain(old_far.iter().flat_map(|(f, m)| f.iter().map(|p| CutPair { lower: m.moved(p, p.lower), ..*p })));
        let count = pairs.clone().filter(is_far).count();
        if count < self.params.min_far_pairs {
            return None;
        }
        let (mut far, mut near) = (Vec::with_capacity(count), Vec::new());
        let mut reach: Real = 0.0;
        for p in pairs {
            if is_far(&p) {
                reach = reach.max(p.box_b.0.norm() + p.box_b.1.norm());
                far.push(p);
            } else {
                near.push(p);
            }
        }
        far.sort_unstable_by(|x, y| x.lower.total_cmp(&y.lower));
        let lower = near.iter().map(|p| p.lower).collect();
        let rel = self.cheap.rel;
        Some(Cut {
            base: std::sync::Arc::new(near),
            lower,
            extra: Vec::new(),
            pose: rel,
            nodes: (self.a.node_count(), self.b.node_count()),
            far: Some(std::sync::Arc::new(FarPairs { pairs: far, pose: rel, reach })),
            far_start: 0,
        })
    }
}
