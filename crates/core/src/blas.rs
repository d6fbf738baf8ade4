//! The BLAS threads of the SDP solves.
//!
//! Clarabel's semidefinite cones factor and multiply their blocks with LAPACK / BLAS: the system
//! OpenBLAS, which this crate links (`openblas-src`). Those blocks are small (a degree-8 body's
//! Gram matrix has 35 rows), and OpenBLAS's pthread build, left to itself, splits calls over one
//! thread per core, whose workers spin in the kernel (`sched_yield`) waiting for work between
//! calls: an 8-part compound fit of the PSB chair on 2 cores took 2.1–2.5 s wall and 0.4–0.9 s of
//! system time that way, against 1.7–1.9 s and 0.03–0.06 s with one thread. The server runs
//! several solves side by side instead (its fit and SDP slots, docs/operations.md).
//!
//! OpenBLAS reads its thread count (`OPENBLAS_NUM_THREADS`) once, in a constructor that runs when
//! the library loads, before `main`: setting the variable from `main` is too late. The binaries
//! call [`init_blas_threads`] first thing instead, which sets one thread through OpenBLAS's own
//! `openblas_set_num_threads` unless the user set `OPENBLAS_NUM_THREADS`.
//!
//! This module holds the crate's only `unsafe` code (the foreign call, and its test's call to
//! OpenBLAS's getter); the crate denies `unsafe_code` everywhere else.

#![allow(unsafe_code)]

use std::os::raw::c_int;
// The crate that links the system OpenBLAS (`-lopenblas`), named so that it is linked whatever
// else the program uses.
use openblas_src as _;

// OpenBLAS's thread-count setter (`cblas.h`: `void openblas_set_num_threads(int num_threads);`).
unsafe extern "C" {
    fn openblas_set_num_threads(num_threads: c_int);
}

/// Sets the number of threads OpenBLAS runs each BLAS / LAPACK call on to `n` (at least 1; a
/// count above `i32::MAX` is clamped). Meant for start-up, before any solve runs: a call that is
/// already running keeps the threads it started with.
pub fn set_blas_threads(n: usize) {
    let n = c_int::try_from(n.max(1)).unwrap_or(c_int::MAX);
    // SAFETY: the function is OpenBLAS's exported setter (the C declaration above), linked into
    // every program that links this crate; it takes one integer by value, reads and writes no
    // memory of ours, and only changes OpenBLAS's own thread count (starting workers under its
    // own lock when the count grows).
    unsafe { openblas_set_num_threads(n) }
}

/// The binaries' BLAS set-up: one OpenBLAS thread per call unless the environment variable
/// `OPENBLAS_NUM_THREADS` is set (to anything but the empty string), in which case OpenBLAS has
/// already read it and it is left alone. Returns whether the count was set here. Call it first
/// thing in `main`.
pub fn init_blas_threads() -> bool {
    let set_by_user = std::env::var_os("OPENBLAS_NUM_THREADS").is_some_and(|v| !v.is_empty());
    if !set_by_user {
        set_blas_threads(1);
    }
    !set_by_user
}

#[cfg(test)]
mod tests {
    use super::*;

    unsafe extern "C" {
        fn openblas_get_num_threads() -> c_int;
    }

    /// The setter reaches the linked OpenBLAS: its own getter reports the count set.
    #[test]
    fn the_thread_count_is_openblas_own() {
        set_blas_threads(1);
        // SAFETY: OpenBLAS's exported getter (`int openblas_get_num_threads(void)`), no arguments.
        assert_eq!(unsafe { openblas_get_num_threads() }, 1);
        set_blas_threads(0);
        // SAFETY: as above.
        assert_eq!(unsafe { openblas_get_num_threads() }, 1, "0 is raised to 1");
    }
}
