//! Gram forms `p = z(x)ᵀ Q z(x)` and Clarabel's packed-triangle convention.
//!
//! A polynomial of degree 2d is a sum of squares iff `p = z(x)ᵀ Q z(x)` for some `Q ⪰ 0`, where
//! `z(x)` is the graded-lex monomial basis of degree ≤ d (paper §II; N = C(n+d, d)). Matching
//! coefficients gives one linear equation per monomial of degree ≤ 2d:
//!
//! ```text
//! coeff_α(p) = Σ_{i ≤ j, zᵢ zⱼ = x^α} (2 − δᵢⱼ) Qᵢⱼ
//! ```
//!
//! Clarabel's `PSDTriangleConeT(N)` stores a symmetric matrix as its upper triangle by columns,
//! off-diagonal entries multiplied by √2 (so the Euclidean inner product is preserved):
//!
//! ```text
//! svec(Q) = [Q₀₀, √2 Q₀₁, Q₁₁, √2 Q₀₂, √2 Q₁₂, Q₂₂, …],   index(i ≤ j) = j(j+1)/2 + i
//! ```
//!
//! In terms of `s = svec(Q)`, the coefficient of an off-diagonal pair is `(2/√2) sₖ = √2 sₖ`.

use super::monomial::graded_exponents;
use std::collections::HashMap;

/// Length of the packed triangle of an `n × n` symmetric matrix, `n(n+1)/2`.
pub fn triangle_len(n: usize) -> usize {
    n * (n + 1) / 2
}

/// Position of entry `(i, j)` (either order) in the packed upper triangle by columns.
pub fn triangle_index(i: usize, j: usize) -> usize {
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    j * (j + 1) / 2 + i
}

/// Weight of packed entry `(i, j)` in the coefficient-matching equations: 1 on the diagonal,
/// √2 off it (see the module docs).
pub fn gram_weight(i: usize, j: usize) -> f64 {
    if i == j {
        1.0
    } else {
        std::f64::consts::SQRT_2
    }
}

/// Unpacks `svec(Q)` into a dense symmetric `n × n` matrix.
pub fn unpack_triangle(s: &[f64], n: usize) -> nalgebra::DMatrix<f64> {
    let mut q = nalgebra::DMatrix::zeros(n, n);
    for j in 0..n {
        for i in 0..=j {
            let v = s[triangle_index(i, j)] / gram_weight(i, j);
            q[(i, j)] = v;
            q[(j, i)] = v;
        }
    }
    q
}

/// The Gram structure of the sos cone in `n` variables at half-degree `d`.
#[derive(Clone, Debug)]
pub struct GramStructure {
    /// The basis z(x) (graded lex, degree ≤ d), length N.
    pub half_basis: Vec<Vec<u8>>,
    /// The basis of degree ≤ 2d in which products are expressed.
    pub full_basis: Vec<Vec<u8>>,
    /// For each packed entry `k = triangle_index(i, j)`: the index in `full_basis` of zᵢ zⱼ.
    pub product_of_entry: Vec<usize>,
    /// Lookup from an exponent vector to its index in `full_basis`.
    pub index_of: HashMap<Vec<u8>, usize>,
}

impl GramStructure {
    /// Builds the structure for `n` variables and half-degree `d` (a 6-variable, d = 3 structure
    /// has N = 84 and 924 monomials of degree ≤ 6).
    pub fn new(n: usize, d: usize) -> Self {
        Self::with_half_basis(n, graded_exponents(n, d), 2 * d)
    }

    /// Builds the structure for an explicit half basis (e.g. the sos-convexity basis y ⊗ z_{d−1}(x))
    /// whose pairwise products have degree ≤ `full_degree`.
    pub fn with_half_basis(n: usize, half_basis: Vec<Vec<u8>>, full_degree: usize) -> Self {
        let full_basis = graded_exponents(n, full_degree);
        let index_of: HashMap<Vec<u8>, usize> = full_basis.iter().cloned().enumerate().map(|(i, e)| (e, i)).collect();
        let m = half_basis.len();
        let mut product_of_entry = vec![0; triangle_len(m)];
        for j in 0..m {
            for i in 0..=j {
                let prod: Vec<u8> = half_basis[i].iter().zip(&half_basis[j]).map(|(a, b)| a + b).collect();
                product_of_entry[triangle_index(i, j)] = index_of[&prod];
            }
        }
        Self { half_basis, full_basis, product_of_entry, index_of }
    }

    /// Side length N of the Gram matrix.
    pub fn size(&self) -> usize {
        self.half_basis.len()
    }

    /// Coefficients (in `full_basis` order) of `z(x)ᵀ Q z(x)` for a dense symmetric `Q`.
    pub fn polynomial_of(&self, q: &nalgebra::DMatrix<f64>) -> Vec<f64> {
        let m = self.size();
        let mut c = vec![0.0; self.full_basis.len()];
        for j in 0..m {
            for i in 0..=j {
                let w = if i == j { 1.0 } else { 2.0 };
                c[self.product_of_entry[triangle_index(i, j)]] += w * q[(i, j)];
            }
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_indices_follow_clarabel() {
        assert_eq!(triangle_index(0, 0), 0);
        assert_eq!(triangle_index(0, 1), 1);
        assert_eq!(triangle_index(1, 1), 2);
        assert_eq!(triangle_index(2, 0), 3);
        assert_eq!(triangle_len(84), 3570);
    }

    #[test]
    fn gram_of_identity_is_sum_of_squared_monomials() {
        // n = 1, d = 2: z = (1, x, x²); zᵀ I z = 1 + x² + x⁴.
        let g = GramStructure::new(1, 2);
        let c = g.polynomial_of(&nalgebra::DMatrix::identity(3, 3));
        assert_eq!(c, vec![1.0, 0.0, 1.0, 0.0, 1.0]);
        // Off-diagonal Q01 = 1/2 gives 2 · ½ · x = x.
        let mut q = nalgebra::DMatrix::zeros(3, 3);
        q[(0, 1)] = 0.5;
        q[(1, 0)] = 0.5;
        assert_eq!(g.polynomial_of(&q), vec![0.0, 1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn unpack_inverts_packing() {
        let s = [1.0, 2.0 * std::f64::consts::SQRT_2, 3.0];
        let q = unpack_triangle(&s, 2);
        assert!((q[(0, 1)] - 2.0).abs() < 1e-15 && q[(1, 1)] == 3.0);
    }
}
