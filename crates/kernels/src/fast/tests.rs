use super::*;
use rand::{Rng, SeedableRng};

#[test]
fn horner_order_covers_the_basis_once() {
    for d in 0..=MAX_DEGREE {
        let e = horner_exponents(d);
        assert_eq!(e.len(), basis_len(3, d));
        let mut seen: Vec<usize> = e.iter().map(|e| index3([e[0] as u8, e[1] as u8, e[2] as u8])).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..basis_len(3, d)).collect::<Vec<_>>());
    }
}

#[test]
fn folded_order_matches_the_folded_schemes() {
    // The row counts of `fold_0` … `fold_6`, and each row's odd partner (a + 1, b, c) is the
    // row of the same (b, c) one power of x up (zero beyond the degree).
    for (d, rows) in [1, 3, 7, 13, 22, 34, 50].into_iter().enumerate() {
        let e = fold_exponents(d);
        assert_eq!(e.len(), rows, "degree {d}");
        assert!(e.iter().all(|e| e[0] % 2 == 0 && e.iter().sum::<usize>() <= d));
    }
    assert_eq!(fold_exponents(6).len(), MAX_FOLDED_ROWS);
}

#[test]
fn pair_table_gives_the_replicated_tables_answers_to_the_bit() {
    // Up to 2d = 6 the four-point kernel reads the replicated table, above it the pair table;
    // each quantity's Horner chain is the same sequence of fused multiply–adds over either, so
    // both give the same bits at every degree.
    if !has_fma() {
        return;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    for degree in 2..=MAX_DEGREE {
        let coeffs: Vec<Real> = (0..basis_len(3, degree)).map(|_| rng.random_range(-1.0..1.0)).collect();
        let fast = FastPoly::new(degree, &coeffs);
        let soa = SoaPoly::new(&fast);
        assert_eq!(matches!(soa.table, SoaTable::Pair(_)), degree > 6, "degree {degree}");
        let rows = soa_rows(&fast);
        let (wide, pair) = (wide_table(&rows), pair_table(&rows));
        let u: [[Real; 4]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.5..1.5)));
        // SAFETY: the CPU runs AVX2 and FMA (checked above).
        let (a, b) = unsafe { (x86::eval4_wide(degree, &wide, &u), x86::eval4_pair(degree, &pair, &u)) };
        assert_eq!(format!("{a:?}"), format!("{b:?}"), "degree {degree}");
    }
}
