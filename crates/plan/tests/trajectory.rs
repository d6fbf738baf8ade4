//! Timed trajectories of planned paths on the Panda among MotionBenchMaker scenes
//! (`data/robots/mbm_panda`, the first two problems of each scenario), timed within the limits of
//! the Panda's MoveIt `joint_limits.yaml` (`data/robots/panda/joint_limits.yaml`): every trajectory
//! starts and ends at rest on the path's ends, keeps within the velocity and acceleration limits
//! to 1e-6 relative at every 1 ms sample, its blends are proven free, and every 1 ms sample checked
//! alone on the meshes is free (the reference, independent of the certificates). Blending beats
//! stopping at every waypoint.

use std::sync::atomic::AtomicBool;
use std::time::Duration;
use sublevel_core::math::{Isometry3, Real};
use sublevel_plan::trajectory::{joint_limits, timed_trajectory, TimingSettings, TrajectoryRequest};
use sublevel_plan::{plan, Goal, PlanSettings, PlanStatus, RobotValidity};
use sublevel_robot::{CheckOptions, FittedRobot, MotionChecker, RobotChecker};
use sublevel_scene::moveit::{allowed_override, world_objects, JointLimitsYaml, MotionPlanRequest, PlanningScene};

fn root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn planned_panda_paths_become_certified_trajectories_within_the_limits() {
    let robot = FittedRobot::load(&root().join("data/robots/panda/panda.robot.json")).unwrap();
    let names: Vec<String> = robot.model.variable_names().iter().map(|s| s.to_string()).collect();
    let file = JointLimitsYaml::from_yaml(&std::fs::read(root().join("data/robots/panda/joint_limits.yaml")).unwrap())
        .unwrap();
    let maps = file.for_joints(&robot.model.variable_names());
    assert_eq!(maps.skipped, ["panda_finger_joint1", "panda_finger_joint2"]);
    let (velocity, acceleration) = (maps.velocity, maps.acceleration);
    let (limits, warnings) = joint_limits(&robot.model, &velocity, &acceleration, &[true; 7]).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(limits.velocity, vec![2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]);
    assert_eq!(limits.acceleration, vec![3.75, 1.875, 2.5, 3.125, 3.75, 5.0, 5.0]);
    let (mut blended_total, mut stopped_total) = (0.0, 0.0);
    for scenario in ["bookshelf_small", "box", "cage", "table_pick"] {
        for problem in 1..=2 {
            let dir = root().join("data/robots/mbm_panda");
            let scene = PlanningScene::from_yaml(
                &std::fs::read(dir.join(format!("scenes/{scenario}/scene{problem:04}.yaml"))).unwrap(),
            )
            .unwrap();
            let request = MotionPlanRequest::from_yaml(
                &std::fs::read(dir.join(format!("requests/{scenario}/request{problem:04}.yaml"))).unwrap(),
            )
            .unwrap();
            let pick = |joints: &[(String, Real)]| -> Vec<Real> {
                names.iter().map(|n| joints.iter().find(|(m, _)| m == n).map_or(0.0, |(_, v)| *v)).collect()
            };
            let (start, goal) = (pick(&request.start), pick(&request.goal));
            let (world, _) = world_objects(&scene).unwrap();
            let allowed = allowed_override(&scene);
            let mut checker = RobotChecker::new(&robot, world.clone(), &allowed).unwrap();
            let mut validity =
                RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), Isometry3::identity(), 0.0);
            let settings = PlanSettings { timeout: Duration::from_secs(20), ..PlanSettings::default() };
            let out = plan(
                &mut validity,
                &start,
                &Goal::Configurations(vec![goal.clone()]),
                &settings,
                &AtomicBool::new(false),
            )
            .unwrap();
            assert_eq!(out.status, PlanStatus::Solved, "{scenario} {problem}");
            let ask = TrajectoryRequest {
                limits: limits.clone(),
                timing: TimingSettings::default(),
                sample_dt: 1e-3,
                max_deviation: 0.1,
            };
            let timed = timed_trajectory(&mut validity, &out.path, &ask, settings.tolerance).unwrap();
            let t = &timed.trajectory;
            let label =
                format!("{scenario} {problem}: {} waypoints, {} blends", out.path.len(), timed.blends.arcs_certified);
            assert_eq!(t.positions[0], start, "{label}");
            assert_eq!(t.positions.last().unwrap(), &goal, "{label}");
            assert!(t.velocities[0].iter().chain(t.velocities.last().unwrap()).all(|v| *v == 0.0));
            assert_eq!(t.time_from_start[0], 0.0);
            assert_eq!(*t.time_from_start.last().unwrap(), t.duration);
            assert!(t.time_from_start.windows(2).all(|w| w[1] > w[0]));
            for (i, (qd, qdd)) in t.velocities.iter().zip(&t.accelerations).enumerate() {
                for j in 0..7 {
                    assert!(
                        qd[j].abs() <= limits.velocity[j] * (1.0 + 1e-6),
                        "{label}: point {i} joint {j} v {}",
                        qd[j]
                    );
                    assert!(
                        qdd[j].abs() <= limits.acceleration[j] * (1.0 + 1e-6),
                        "{label}: point {i} joint {j} a {}",
                        qdd[j]
                    );
                }
            }
            // Positions agree with the velocities (trapezoid rule, an error of O(a·dt²)).
            for k in 1..t.positions.len() {
                let dt = t.time_from_start[k] - t.time_from_start[k - 1];
                for j in 0..7 {
                    let predicted = (t.velocities[k][j] + t.velocities[k - 1][j]) / 2.0 * dt;
                    let moved = t.positions[k][j] - t.positions[k - 1][j];
                    assert!(
                        (moved - predicted).abs() <= limits.acceleration[j] * dt * dt,
                        "{label}: point {k} joint {j}: moved {moved} predicted {predicted} dt {dt} of {} v {} {} a {} {}",
                        t.positions.len(),
                        t.velocities[k - 1][j],
                        t.velocities[k][j],
                        t.accelerations[k - 1][j],
                        t.accelerations[k][j]
                    );
                }
            }
            // Every 1 ms sample checked alone on the meshes.
            let mut dense = RobotChecker::new(&robot, world.clone(), &allowed).unwrap();
            let options = CheckOptions { distance: false, ..CheckOptions::default() };
            for (i, q) in t.positions.iter().enumerate() {
                assert!(!dense.check(q, &Isometry3::identity(), &options).unwrap().collides, "{label}: sample {i}");
            }
            // Stopping at every waypoint instead.
            let stop = TrajectoryRequest { max_deviation: 0.0, ..ask };
            let stopped = timed_trajectory(&mut validity, &out.path, &stop, settings.tolerance).unwrap();
            assert!(t.duration <= stopped.trajectory.duration + 1e-9, "{label}");
            blended_total += t.duration;
            stopped_total += stopped.trajectory.duration;
            eprintln!(
                "{label}: {:.3} s blended ({} tightened, {} stops), {:.3} s stopping, stage {:.2} ms",
                t.duration,
                timed.blends.tightened,
                timed.stops,
                stopped.trajectory.duration,
                timed.seconds * 1e3
            );
        }
    }
    eprintln!("total {blended_total:.3} s blended, {stopped_total:.3} s stopping");
    assert!(blended_total < stopped_total);
}
