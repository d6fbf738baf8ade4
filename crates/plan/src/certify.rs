//! Certified paths: every edge of a returned path proven free by conservative advancement
//! ([`Validity::certify`]), with no sampling resolution. Sampled edges can pass through an
//! obstacle between their samples; an edge the certificate rejects is repaired:
//!
//! ```text
//! certify(a, b) at the tolerance          → free: keep it
//! at a hundredth of the tolerance         → free: keep it (an end within the tolerance of an
//!                                           obstacle, as grasp configurations are)
//! split at the middle m (m free): certify a → m and m → b the same way, up to `max_depth` halvings
//! otherwise re-plan a → b by RRT-Connect whose edges are themselves certified, in the time left
//! ```
//!
//! A path whose every edge passed is certified; an edge still unproven at the deadline leaves the
//! path uncertified (and says which edges).

use crate::rrt::{connect, Budget, SearchSettings};
use crate::space::HaltonSampler;
use crate::validity::{Certificate, CheckCounts, Validity};
use rand::Rng;
use sublevel_core::math::Real;
use sublevel_core::Result;

/// Settings of [`certify_path`].
#[derive(Clone, Copy, Debug)]
pub struct CertifySettings {
    /// Contact tolerance of the certificates (meters, > 0).
    pub tolerance: Real,
    /// Most halvings of one edge before it is re-planned.
    pub max_depth: usize,
    /// The search settings of a re-plan.
    pub search: SearchSettings,
}

/// A path after certification.
#[derive(Clone, Debug)]
pub struct CertifiedPath {
    /// The waypoints (repairs may have added some).
    pub path: Vec<Vec<Real>>,
    /// Indices of the edges (`path[i] → path[i+1]`) left unproven; empty for a certified path.
    pub unproven: Vec<usize>,
    /// Edges repaired (split or re-planned).
    pub repaired: usize,
}

/// Certifies every edge of `path`, repairing those that fail (module docs).
///
/// # Errors
/// The checker's errors.
pub fn certify_path(
    checker: &mut dyn Validity,
    path: &[Vec<Real>],
    settings: &CertifySettings,
    rng: &mut impl Rng,
    budget: Budget<'_>,
) -> Result<CertifiedPath> {
    let mut out = CertifiedPath { path: vec![path[0].clone()], unproven: Vec::new(), repaired: 0 };
    for w in path.windows(2) {
        let piece = certify_edge(checker, &w[0], &w[1], settings, 0, rng, budget)?;
        match piece {
            Some(piece) => {
                out.repaired += usize::from(piece.len() > 2);
                out.path.extend(piece.into_iter().skip(1));
            }
            None => {
                out.unproven.push(out.path.len() - 1);
                out.path.push(w[1].clone());
            }
        }
    }
    Ok(out)
}

/// The edge `a → b` as a certified piece (`a` first, `b` last), or `None` when it could not be
/// proven by the deadline.
fn certify_edge(
    checker: &mut dyn Validity,
    a: &[Real],
    b: &[Real],
    settings: &CertifySettings,
    depth: usize,
    rng: &mut impl Rng,
    budget: Budget<'_>,
) -> Result<Option<Vec<Vec<Real>>>> {
    if proven(checker, a, b, settings.tolerance)? {
        return Ok(Some(vec![a.to_vec(), b.to_vec()]));
    }
    if budget.stopped().is_some() {
        return Ok(None);
    }
    if depth < settings.max_depth {
        let mut m = Vec::new();
        checker.space().interpolate(a, b, 0.5, &mut m);
        if checker.state_free(&m)? {
            if let Some(first) = certify_edge(checker, a, &m, settings, depth + 1, rng, budget)? {
                if let Some(second) = certify_edge(checker, &m, b, settings, depth + 1, rng, budget)? {
                    let mut piece = first;
                    piece.extend(second.into_iter().skip(1));
                    return Ok(Some(piece));
                }
            }
            return Ok(None);
        }
    }
    // Re-plan a → b with certified edges.
    let mut certified = Certified { inner: checker, tolerance: settings.tolerance };
    let mut sampler = HaltonSampler::new(a.len(), rng);
    Ok(connect(&mut certified, a, &[b.to_vec()], &settings.search, &mut sampler, rng, budget)?
        .ok()
        .map(|found| found.path))
}

/// The finest contact tolerance (meters) the certificates of a plan at `tolerance` use: a
/// hundredth of it ([`proven`]). A motion check of a certified edge at the plan's padding and
/// this tolerance answers free; at a coarser one it may report a contact within the tolerance
/// (an edge that passes closer than the tolerance to the padding, never through it).
pub fn certificate_tolerance(tolerance: Real) -> Real {
    tolerance / 100.0
}

/// Whether the edge `a → b` is proven free at `tolerance`, or else at a hundredth of it (an end
/// within the tolerance of an obstacle, as grasp configurations and points the simplification
/// put on an edge can be).
fn proven(checker: &mut dyn Validity, a: &[Real], b: &[Real], tolerance: Real) -> Result<bool> {
    Ok(checker.certify(a, b, tolerance)? == Certificate::Free
        || checker.certify(a, b, certificate_tolerance(tolerance))? == Certificate::Free)
}

/// A checker whose edge test is the certificate (a re-plan's edges are proven as they are made).
struct Certified<'a> {
    inner: &'a mut dyn Validity,
    tolerance: Real,
}

impl Validity for Certified<'_> {
    fn space(&self) -> &crate::space::JointSpace {
        self.inner.space()
    }
    fn state_free(&mut self, q: &[Real]) -> Result<bool> {
        self.inner.state_free(q)
    }
    fn edge_free(&mut self, a: &[Real], b: &[Real], _resolution: Real) -> Result<bool> {
        proven(self.inner, a, b, self.tolerance)
    }
    fn certify(&mut self, a: &[Real], b: &[Real], tolerance: Real) -> Result<Certificate> {
        self.inner.certify(a, b, tolerance)
    }
    fn certify_tube(&mut self, a: &[Real], b: &[Real], tube: &[Real], tolerance: Real) -> Result<Certificate> {
        self.inner.certify_tube(a, b, tube, tolerance)
    }
    fn box_free(&mut self, center: &[Real], tube: &[Real]) -> Result<bool> {
        self.inner.box_free(center, tube)
    }
    fn counts(&self) -> CheckCounts {
        self.inner.counts()
    }
    fn collision(&mut self, q: &[Real]) -> Result<Option<String>> {
        self.inner.collision(q)
    }
    fn set_search_margin(&mut self, margin: Real) {
        self.inner.set_search_margin(margin);
    }
}
