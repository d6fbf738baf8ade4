//! The same queries in this process: a [`Catalog`] in a temporary directory holding the load
//! test's scene, queried on one thread, for the gRPC / in-process ratio.

use super::report::InProcess;
use super::scene::{chair_pose, demo_body, isometry, Layout, Op, OpPicker, CHAIR_HOME, CHAIR_JSON, HUMAN_JSON};
use super::{LoadtestArgs, StreamQuery};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use sublevel::query::NewtonParams;
use sublevel::scene::planner::{PlannerRequest, QueryView};
use sublevel::scene::store::RedbStore;
use sublevel::scene::{Catalog, QueryKind, QueryOptions, QueryPair};
use sublevel::Result;

/// A catalog in a temporary directory holding the load test's scene, deleted on drop.
pub(super) struct LocalScene {
    catalog: Option<Catalog>,
    dir: PathBuf,
    pub(super) scene: String,
    pub(super) chair: String,
    pub(super) humans: Vec<String>,
}

impl Drop for LocalScene {
    fn drop(&mut self) {
        self.catalog = None;
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl LocalScene {
    /// The scene of `layout` in a fresh catalog in a temporary directory.
    pub(super) fn new(layout: &Layout) -> Result<Self> {
        let dir = std::env::temp_dir().join(format!(
            "sublevel-loadtest-{}-{:016x}",
            std::process::id(),
            rand::random::<u64>()
        ));
        std::fs::create_dir_all(&dir)?;
        let mut local = LocalScene {
            catalog: None,
            dir: dir.clone(),
            scene: String::new(),
            chair: String::new(),
            humans: Vec::new(),
        };
        let catalog = Catalog::open(Box::new(RedbStore::open_dir(&dir)?), NewtonParams::default())?;
        let chair_body = catalog.add_body("chair_101", demo_body("chair_101", CHAIR_JSON)?)?;
        let human_body = catalog.add_body("human_10", demo_body("human_10", HUMAN_JSON)?)?;
        local.scene = catalog.create_scene("loadtest")?;
        local.chair = catalog.add_instance(&local.scene, &chair_body, isometry(&CHAIR_HOME)?)?;
        for h in &layout.humans {
            local.humans.push(catalog.add_instance(&local.scene, &human_body, isometry(h)?)?);
        }
        local.catalog = Some(catalog);
        Ok(local)
    }

    /// The catalog (open until dropped).
    pub(super) fn catalog(&self) -> &Catalog {
        self.catalog.as_ref().expect("open until dropped")
    }

    /// Pair `j` of the layout (the chair and its human) as a query of `kind`.
    pub(super) fn pair(&self, layout: &Layout, j: usize, kind: QueryKind, margin: f64) -> QueryPair {
        QueryPair {
            kind,
            first: self.chair.clone(),
            second: self.humans[layout.pair_humans[j]].clone(),
            options: QueryOptions::default(),
            margin,
        }
    }
}

/// Pair queries per second of the scenario's requests run on a [`Catalog`] in this process, on
/// this thread, for about `seconds`.
pub(super) fn in_process(args: &LoadtestArgs, layout: &Layout, seconds: Duration) -> Result<InProcess> {
    let local = LocalScene::new(layout)?;
    let catalog = local.catalog();
    let k = args.pairs;
    let batch: Vec<QueryPair> = (0..k).map(|j| local.pair(layout, j, QueryKind::Distance, 0.0)).collect();
    let (kind, margin) = match args.stream_query {
        StreamQuery::Distance => (QueryKind::Distance, 0.0),
        StreamQuery::Collide => (QueryKind::Collide, args.margin),
    };
    let queries: Vec<QueryPair> = (0..k).map(|j| local.pair(layout, j, kind, margin)).collect();
    // The columns form (distinct ids, repeats allowed: the in-process cost does not depend on it).
    let column_ids: Vec<String> =
        std::iter::once(batch[0].first.clone()).chain(batch.iter().map(|q| q.second.clone())).collect();
    let mut view = QueryView::new(&local.scene);
    let mut picker = OpPicker::new(args.scenario, 0);
    let mut pairs = 0u64;
    let start = Instant::now();
    while start.elapsed() < seconds {
        match picker.next() {
            Op::Unary => {
                let j = picker.next_unary_pair(k);
                let q = &batch[j];
                catalog.distance(&local.scene, &q.first, &q.second)?;
                pairs += 1;
            }
            Op::Batch if args.columns => {
                let (first, second): (Vec<u32>, Vec<u32>) = (0..k as u32).map(|j| (0, j + 1)).unzip();
                let answers = catalog.batch_columns(
                    &local.scene,
                    &column_ids,
                    (&first, &second),
                    QueryKind::Distance,
                    Default::default(),
                    0.0,
                )?;
                pairs += answers.len() as u64;
            }
            Op::Batch => pairs += catalog.batch(&local.scene, &batch)?.len() as u64,
            Op::Stream => {
                let step = picker.next_step();
                let request = PlannerRequest {
                    poses: vec![(local.chair.clone(), isometry(&chair_pose(0, 1, step))?)],
                    queries: queries.clone(),
                    ..PlannerRequest::default()
                };
                pairs += match view.run(catalog, &request)? {
                    sublevel::scene::planner::PlannerAnswers::Single(a) => a.len() as u64,
                    sublevel::scene::planner::PlannerAnswers::PerState(s) => {
                        s.iter().map(Vec::len).sum::<usize>() as u64
                    }
                };
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    Ok(InProcess { pair_queries_per_s: pairs as f64 / seconds, seconds })
}
