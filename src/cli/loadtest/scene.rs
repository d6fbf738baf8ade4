//! The load test's scene and scenarios: where the chair and the humans stand, the chair's path
//! through the stream scenario, and which operation each request of a task is.

use super::Scenario;
use sublevel::body::BodyFile;
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::service::pb;
use sublevel::{Body, Error, Result};

/// The demo chair (a degree-4 fit of `chair_101.off`, in body-file JSON).
pub(super) const CHAIR_JSON: &str = include_str!("../../../data/demo/chair_101.json");
/// The demo human (a degree-4 fit of `human_10.off`, in body-file JSON).
pub(super) const HUMAN_JSON: &str = include_str!("../../../data/demo/human_10.json");
/// Most humans placed around the chair (more pairs repeat them).
const MAX_HUMANS: usize = 32;
/// Steps of one lap of the chair's path.
pub(super) const PATH_STEPS: u64 = 4000;
/// Amplitude of the chair's path (meters).
const PATH_AMPLITUDE: f64 = 0.3;
/// Amplitude of the chair's turn about z along its path (radians).
const PATH_TURN: f64 = 0.3;
/// Ring radius of the humans, in units of the sum of the two bodies' normalization scales.
const RING: f64 = 0.9;
/// Share of unary / batch requests in the mixed scenario, in percent (the rest are stream steps).
const MIXED_UNARY_PERCENT: u64 = 20;
/// See [`MIXED_UNARY_PERCENT`].
const MIXED_BATCH_PERCENT: u64 = 30;

/// A pose as a unit quaternion `(w, x, y, z)` and a translation (meters).
pub(super) type Parts = ([f64; 4], [f64; 3]);

/// The bodies and where they stand.
#[derive(Clone, Debug)]
pub(super) struct Layout {
    /// Pose of every human.
    pub(super) humans: Vec<Parts>,
    /// Human index of the second instance of pair j (the first is always the chair).
    pub(super) pair_humans: Vec<usize>,
}

fn turn_z(angle: f64) -> [f64; 4] {
    [(0.5 * angle).cos(), 0.0, 0.0, (0.5 * angle).sin()]
}

/// One of the embedded demo bodies, parsed and checked.
pub(super) fn demo_body(name: &str, json: &str) -> Result<Body> {
    let file: BodyFile = serde_json::from_str(json)?;
    Body::from_file(file).map_err(|e| Error::invalid(format!("embedded demo body {name}"), e.to_string()))
}

impl Layout {
    /// `min(pairs, 32)` humans on a ring around the chair (radius [`RING`] × the sum of the scales,
    /// ± 15 % in turn), each turned towards the chair.
    pub(super) fn new(pairs: usize) -> Result<Self> {
        let ring = RING * (demo_body("chair_101", CHAIR_JSON)?.scale() + demo_body("human_10", HUMAN_JSON)?.scale());
        let n = pairs.clamp(1, MAX_HUMANS);
        let humans = (0..n)
            .map(|j| {
                let phi = std::f64::consts::TAU * j as f64 / n as f64;
                let r = ring * (1.0 + 0.15 * ((j % 3) as f64 - 1.0));
                (turn_z(phi + std::f64::consts::PI), [r * phi.cos(), r * phi.sin(), 0.0])
            })
            .collect();
        Ok(Self { humans, pair_humans: (0..pairs).map(|j| j % n).collect() })
    }
}

/// The chair's stored pose (unary, batch): the identity.
pub(super) const CHAIR_HOME: Parts = ([1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]);

/// The chair's pose at step `step` of task `task` of `tasks`: a smooth closed path, the tasks
/// starting at evenly spaced points of it.
pub(super) fn chair_pose(task: usize, tasks: usize, step: u64) -> Parts {
    let s = step + (task as u64 * PATH_STEPS) / tasks.max(1) as u64;
    let phi = std::f64::consts::TAU * (s % PATH_STEPS) as f64 / PATH_STEPS as f64;
    let t = [PATH_AMPLITUDE * phi.cos(), 0.5 * PATH_AMPLITUDE * (2.0 * phi).sin(), 0.0];
    (turn_z(PATH_TURN * phi.sin()), t)
}

/// A pose as the proto's `Pose`.
pub(super) fn proto_pose(p: &Parts) -> pb::Pose {
    let (q, t) = p;
    pb::Pose {
        rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
        translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
    }
}

/// A pose as an isometry (a unit quaternion is checked).
pub(super) fn isometry(p: &Parts) -> Result<Isometry3> {
    pose_from_parts("pose", p.0, p.1)
}

/// The kind of one request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Op {
    /// One `Distance` call.
    Unary = 0,
    /// One `BatchQuery` of the K pairs.
    Batch = 1,
    /// One step of the task's `QueryStream`.
    Stream = 2,
}

/// Every operation, in the order of the report's per-operation lines.
pub(super) const OPS: [Op; 3] = [Op::Unary, Op::Batch, Op::Stream];

impl Op {
    /// The operation's name in the report.
    pub(super) fn name(self) -> &'static str {
        match self {
            Op::Unary => "unary",
            Op::Batch => "batch",
            Op::Stream => "stream",
        }
    }
}

/// A small deterministic generator (splitmix64) for the mixed scenario's choices.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// Picks the operations of one task, and what each asks.
pub(super) struct OpPicker {
    scenario: Scenario,
    rng: SplitMix,
    unary: u64,
    step: u64,
    /// The task's index (its start on the chair's path, its first unary pair).
    pub(super) task: usize,
}

impl OpPicker {
    /// The picker of task `task` (its own fixed pseudo-random sequence).
    pub(super) fn new(scenario: Scenario, task: usize) -> Self {
        Self { scenario, rng: SplitMix(0x5EED_0000 + task as u64), unary: 0, step: 0, task }
    }

    /// The operation of the next request.
    pub(super) fn next(&mut self) -> Op {
        match self.scenario {
            Scenario::Unary => Op::Unary,
            Scenario::Batch => Op::Batch,
            Scenario::Stream => Op::Stream,
            Scenario::Mixed => match self.rng.next() % 100 {
                x if x < MIXED_UNARY_PERCENT => Op::Unary,
                x if x < MIXED_UNARY_PERCENT + MIXED_BATCH_PERCENT => Op::Batch,
                _ => Op::Stream,
            },
        }
    }

    /// The pair of the next unary request.
    pub(super) fn next_unary_pair(&mut self, pairs: usize) -> usize {
        let j = (self.task as u64 + self.unary) % pairs as u64;
        self.unary += 1;
        j as usize
    }

    /// The step of the next stream request.
    pub(super) fn next_step(&mut self) -> u64 {
        self.step += 1;
        self.step - 1
    }
}
