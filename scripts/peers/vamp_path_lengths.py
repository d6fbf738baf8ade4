#!/usr/bin/env python3
"""VAMP's simplified path lengths on the MotionBenchMaker Panda problems, per scenario.

The planning comparison of docs/planning.md sets the lengths of the paths `sublevel-plan` returns
(the `median length` column of the lab's `plan_mbm` example: the sum of the waypoints' Euclidean
joint-space distances) beside VAMP's: RRT-Connect with VAMP's own defaults
(`vamp.configure_robot_and_planner_with_kwargs("panda", "rrtc")`), the Halton sampler reset before
each problem, then VAMP's `simplify`; the length is the simplified path's `cost()`, the same sum.

    python scripts/peers/vamp_path_lengths.py --problems-pkl PROBLEMS.pkl [--limit 100]

Run it with a Python that has VAMP installed (`vamp-planner`, e.g. the robots peer's venv);
PROBLEMS.pkl is the problem set VAMP converts from the MotionBenchMaker archive
(`resources/panda/problems.pkl` of VAMP's source distribution). Neither is part of this repository.
Prints one line per scenario: problems solved and the median simplified length.
"""
import argparse
import pickle

import numpy as np
import vamp

SCENARIOS = ["bookshelf_small", "bookshelf_tall", "bookshelf_thin", "box", "cage", "table_pick", "table_under_pick"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems-pkl", required=True, help="VAMP's problems.pkl")
    ap.add_argument("--limit", type=int, default=100, help="problems per scenario (default 100)")
    args = ap.parse_args()
    with open(args.problems_pkl, "rb") as f:
        problems = pickle.load(f)
    vm, planner, plan_settings, simplify_settings = vamp.configure_robot_and_planner_with_kwargs("panda", "rrtc")
    sampler = vm.halton()
    for name in SCENARIOS:
        lengths = []
        for data in problems["problems"][name][: args.limit]:
            if not data["valid"]:
                continue
            env = vamp.problem_dict_to_vamp(data)
            sampler.reset()
            result = planner(data["start"], data["goals"], env, plan_settings, sampler)
            if not result.solved:
                continue
            simple = vm.simplify(result.path, env, simplify_settings, sampler)
            lengths.append(simple.path.cost())
        median = float(np.median(lengths)) if lengths else float("nan")
        print(f"{name} solved {len(lengths)} median simplified length {median:.3f}")


if __name__ == "__main__":
    main()
