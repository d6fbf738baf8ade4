//! The lab's examples that the README names, run as a user runs them (from the repository root),
//! so an example cannot break unnoticed. `cargo test` builds the examples beside the test binaries
//! (`target/debug/examples/`).

use std::path::{Path, PathBuf};
use std::process::Command;

/// An example binary built by `cargo test` next to this test's directory.
fn example(name: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().and_then(Path::parent).unwrap().join("examples");
    let path = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(path.is_file(), "{} is not built (cargo test builds the examples)", path.display());
    path
}

fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `plan_mbm` (`sublevel-plan` in process, the README's tour) on the first problem of two
/// scenarios: every problem solved with a certified path (the sampling is seeded, so the run is
/// the same every time; the timeout leaves a debug build room).
#[test]
fn plan_mbm_solves_its_first_problems_with_certified_paths() {
    let out = Command::new(example("plan_mbm"))
        .current_dir(repository())
        .args(["--scenarios", "bookshelf_small,box", "--limit", "1", "--timeout", "30"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    for scenario in ["bookshelf_small", "box"] {
        let row =
            stdout.lines().find(|l| l.starts_with(&format!("| {scenario} |"))).unwrap_or_else(|| panic!("{stdout}"));
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        assert_eq!((cells[2], cells[3]), ("1", "1"), "problems and solved: {row}");
    }
}
