//! Monomial bases in graded lexicographic order.
//!
//! A monomial `x₁^a₁ ⋯ xₙ^aₙ` is stored as its exponent vector `[a₁, …, aₙ]`. The basis of all
//! monomials of degree ≤ d in n variables has `N = C(n + d, d)` elements (paper §II: for n = 3,
//! N = 4, 10, 20, 35 at d = 1, 2, 3, 4). Its order, used everywhere in the crate (body files,
//! Gram matrices, SDP rows), is **graded lexicographic**:
//!
//! ```text
//! by total degree ascending, then by exponent vector descending (lexicographically):
//! n = 3, d = 2:  1, x, y, z, x², xy, xz, y², yz, z²
//! ```

/// Number of monomials of degree ≤ `d` in `n` variables, `C(n + d, d)`.
pub fn basis_len(n: usize, d: usize) -> usize {
    let mut num: usize = 1;
    for k in 1..=n {
        num = num * (d + k) / k;
    }
    num
}

/// All exponent vectors of total degree exactly `k` in `n` variables, lexicographically descending.
pub fn exponents_of_degree(n: usize, k: usize) -> Vec<Vec<u8>> {
    fn rec(n: usize, k: usize, prefix: &mut Vec<u8>, out: &mut Vec<Vec<u8>>) {
        if n == 1 {
            prefix.push(k as u8);
            out.push(prefix.clone());
            prefix.pop();
            return;
        }
        for a in (0..=k).rev() {
            prefix.push(a as u8);
            rec(n - 1, k - a, prefix, out);
            prefix.pop();
        }
    }
    let mut out = Vec::new();
    if n == 0 {
        if k == 0 {
            out.push(Vec::new());
        }
        return out;
    }
    rec(n, k, &mut Vec::with_capacity(n), &mut out);
    out
}

/// The graded-lex basis of all monomials of degree ≤ `d` in `n` variables (length
/// [`basis_len`]`(n, d)`).
pub fn graded_exponents(n: usize, d: usize) -> Vec<Vec<u8>> {
    (0..=d).flat_map(|k| exponents_of_degree(n, k)).collect()
}

/// The trivariate graded-lex basis of degree ≤ `d` as fixed-size exponent triples `[a, b, c]`
/// (the monomial `x^a y^b z^c`).
pub fn graded_exponents3(d: usize) -> Vec<[u8; 3]> {
    graded_exponents(3, d).into_iter().map(|e| [e[0], e[1], e[2]]).collect()
}

/// Position of the trivariate monomial `[a, b, c]` in the graded-lex basis, in O(1).
///
/// Monomials of degree < k = a+b+c come first (`C(k+2, 3)` of them); within degree k the order
/// is `a` descending, then `b` descending.
pub fn index3(e: [u8; 3]) -> usize {
    let (a, b) = (e[0] as usize, e[1] as usize);
    let k = a + b + e[2] as usize;
    let before = if k == 0 { 0 } else { basis_len(3, k - 1) };
    // Within degree k: blocks for a = k, k-1, ..., each block for a has (k - a + 1) entries.
    let r = k - a; // remaining degree for (b, c)
    let offset_a = r * (r + 1) / 2; // entries with larger a: sum_{j=0}^{r-1} (j+1)
    before + offset_a + (r - b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_match_binomials() {
        assert_eq!(basis_len(3, 1), 4);
        assert_eq!(basis_len(3, 2), 10);
        assert_eq!(basis_len(3, 3), 20);
        assert_eq!(basis_len(3, 4), 35);
        assert_eq!(basis_len(3, 8), 165);
        assert_eq!(basis_len(6, 3), 84);
        for n in 1..=6 {
            for d in 0..=4 {
                assert_eq!(graded_exponents(n, d).len(), basis_len(n, d));
            }
        }
    }

    #[test]
    fn order_is_graded_lex() {
        let b = graded_exponents3(2);
        let names: Vec<[u8; 3]> = vec![
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [2, 0, 0],
            [1, 1, 0],
            [1, 0, 1],
            [0, 2, 0],
            [0, 1, 1],
            [0, 0, 2],
        ];
        assert_eq!(b, names);
    }

    #[test]
    fn index3_inverts_the_basis() {
        for (i, e) in graded_exponents3(8).into_iter().enumerate() {
            assert_eq!(index3(e), i, "{e:?}");
        }
    }
}
