use super::*;

/// A random `r × c` matrix with about half its entries exactly zero.
pub(crate) fn pattern(r: usize, c: usize, seed: u64) -> DMatrix<f64> {
    let mut s = seed;
    DMatrix::from_fn(r, c, |_, _| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let v = ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
        if v.abs() < 0.5 { 0.0 } else { v }
    })
}

/// A row of `S M` read from the columns of `S` (or of `Sᵀ` for an `S` that is not
/// symmetric) is that row of `right_mul`'s product, and `Mᵀ (S N)` from those rows is
/// `tr_mul_add` on the whole product, bit for bit: with zeros of both signs in `S`, empty
/// and dense columns in `M` and `N`, and a dirty output.
#[test]
fn products_from_rows_are_the_whole_products_to_the_bit() {
    for seed in 0..60 {
        let (n, q) = (9, [9, 4, 1][seed as usize % 3]);
        let signed = |v: f64| if v == 0.0 && seed % 2 == 0 { -0.0 } else { v };
        let raw = pattern(n, n, seed + 300).map(signed);
        let symmetric = seed % 4 != 3;
        let s = if symmetric {
            &raw + raw.transpose()
        } else {
            raw.clone()
        };
        let s_rows = if symmetric { s.clone() } else { s.transpose() };
        let mut nm = pattern(n, q, seed + 400);
        nm.column_mut(seed as usize % q).fill(0.0);
        let mut m = pattern(n, 3, seed + 500);
        m.column_mut(seed as usize % 3).fill(0.0);
        let (mut sp_n, mut sp_m) = (SparseColumns::new(n, q), SparseColumns::new(n, 3));
        sp_n.assign(&nm);
        sp_m.assign(&m);
        let mut whole = DMatrix::from_element(n, q, f64::NAN);
        sp_n.right_mul(&s, &mut whole);
        let mut row = vec![f64::NAN; q];
        for i in 0..n {
            sp_n.product_row(&s_rows, i, &mut row);
            for (c, r) in row.iter().enumerate() {
                assert_eq!(
                    r.to_bits(),
                    whole[(i, c)].to_bits(),
                    "seed {seed} ({i}, {c})"
                );
            }
        }
        let start = pattern(3, q, seed + 600);
        let (mut want, mut got) = (start.clone(), start);
        sp_m.tr_mul_add(0.5, &whole, &mut want);
        let mut scratch = Vec::new();
        sp_m.tr_mul_product_add(0.5, &s_rows, &sp_n, &mut scratch, &mut got);
        for (g, w) in got.iter().zip(want.iter()) {
            assert_eq!(g.to_bits(), w.to_bits(), "seed {seed}: {g} vs {w}");
        }
    }
}

/// `right_mul` writes what clearing the product and `right_mul_add` write, bit for bit
/// (signs of zeros included), over empty, sparse and dense columns and a dirty `out`.
#[test]
fn the_product_without_clearing_is_the_cleared_one_to_the_bit() {
    for seed in 0..50 {
        let mut m = pattern(9, 6, seed);
        m.column_mut(seed as usize % 6).fill(0.0);
        m.column_mut((seed as usize + 1) % 6).fill(-0.0);
        let s = pattern(5, 9, seed + 100).map(|v| if v == 0.0 { -0.0 } else { v * 1e6 });
        let mut sp = SparseColumns::new(9, 6);
        sp.assign(&m);
        let same = |got: &DMatrix<f64>, want: &DMatrix<f64>| {
            for (g, w) in got.iter().zip(want.iter()) {
                assert_eq!(g.to_bits(), w.to_bits(), "seed {seed}: {g} vs {w}");
            }
        };
        let mut want = DMatrix::zeros(5, 6);
        sp.right_mul_add(&s, &mut want);
        let mut got = DMatrix::from_element(5, 6, f64::NAN);
        sp.right_mul(&s, &mut got);
        same(&got, &want);
    }
}

#[test]
fn products_match_dense() {
    let m = pattern(7, 5, 1);
    let s = pattern(6, 7, 2);
    let x = pattern(7, 3, 3);
    let v = pattern(7, 1, 4);
    let mut sp = SparseColumns::new(7, 5);
    sp.assign(&m);
    assert!(sp.nnz() < 35);
    let mut out = DMatrix::from_element(6, 5, 3.0);
    sp.right_mul(&s, &mut out);
    assert!((&out - &s * &m).norm() < 1e-12);
    sp.right_mul_add(&s, &mut out);
    assert!((&out - 2.0 * &s * &m).norm() < 1e-12);
    let mut acc = DMatrix::from_element(5, 3, 1.0);
    sp.tr_mul_add(2.0, &x, &mut acc);
    let want = DMatrix::from_element(5, 3, 1.0) + 2.0 * m.transpose() * &x;
    assert!((&acc - want).norm() < 1e-12);
    let mut y = vec![0.5; 5];
    sp.tr_mul_vec_add(-1.0, v.as_slice(), &mut y);
    let want = DMatrix::from_element(5, 1, 0.5) - m.transpose() * &v;
    assert!(
        y.iter()
            .zip(want.iter())
            .all(|(a, b)| (a - b).abs() < 1e-12)
    );
}

/// Columns of many 8-row blocks (and a last partial one), refilled with a sparser, a
/// denser and a pattern of single nonzeros among negative zeros, with NaNs and infinities:
/// exactly the entries `!= 0.0`, in row order, each time.
#[test]
fn refills_hold_exactly_the_nonzeros() {
    let mut sp = SparseColumns::new(150, 4);
    for seed in [5, 6, 7] {
        let mut m = pattern(150, 4, seed);
        if seed == 5 {
            m.view_mut((0, 0), (100, 4)).fill(0.0);
        }
        if seed == 7 {
            // One entry per block at most, the rest negative zeros, and the special values.
            m = m.map(|v| if v.abs() < 0.95 { -0.0 } else { v });
            m[(3, 0)] = f64::NAN;
            m[(149, 1)] = f64::INFINITY;
            m[(8, 2)] = -f64::MIN_POSITIVE / 4.0;
        }
        sp.assign(&m);
        let nonzeros = m.iter().filter(|v| **v != 0.0).count();
        assert_eq!(sp.nnz(), nonzeros);
        let mut back = DMatrix::zeros(150, 4);
        for j in 0..4 {
            let (rows, vals) = sp.column(j);
            assert!(rows.windows(2).all(|w| w[0] < w[1]));
            for (&i, &v) in rows.iter().zip(vals) {
                back[(i, j)] = v;
            }
        }
        let same = back.iter().zip(m.iter());
        assert!(
            same.clone()
                .all(|(b, v)| b == v || (b.is_nan() && v.is_nan()))
        );
        assert!(same.filter(|(_, v)| **v != 0.0).count() == nonzeros);
    }
}

/// A refill by a support with unit columns (a shift register's, as the delayed plant
/// declares) holds what a refill of the whole matrix holds, the units' ones included, and
/// a refill by ranges reads nothing outside them (junk there is not picked up).
#[test]
fn a_refill_by_the_support_is_the_whole_refill() {
    let (n, c) = (12, 7);
    let mut m = pattern(n, c, 11);
    m.view_mut((4, 0), (n - 4, 3)).fill(0.0);
    let mut columns = vec![Column::Rows(0..4); 3];
    for j in 3..c {
        m.column_mut(j).fill(0.0);
        m[(j + 2, j)] = 1.0;
        columns.push(Column::Unit(j + 2));
    }
    let (mut whole, mut by_support) = (SparseColumns::new(n, c), SparseColumns::new(n, c));
    whole.assign(&m);
    by_support.assign_support(&m, &columns);
    for j in 0..c {
        assert_eq!(whole.column(j), by_support.column(j), "column {j}");
    }
    let mut junk = m.clone();
    junk.view_mut((4, 0), (n - 4, 3)).fill(7.0);
    let rows: Vec<Range<usize>> = (0..c)
        .map(|j| if j < 3 { 0..4 } else { j + 2..j + 3 })
        .collect();
    by_support.assign_within(&junk, Some(&rows));
    for j in 0..c {
        assert_eq!(
            whole.column(j),
            by_support.column(j),
            "column {j} by ranges"
        );
    }
}

/// Room made by a support holds exactly what the support allows, and refills within it
/// keep their storage (a support one entry short would move it); without a support,
/// room for every entry.
#[test]
fn room_made_by_a_support_holds_its_refills() {
    let (n, m, p) = (6, 2, 2);
    // Nonzero wherever the support allows, zero elsewhere.
    let dense = |r: usize, c: usize, seed: f64| {
        DMatrix::from_fn(r, c, |i, j| seed + (i * c + j) as f64 / 8.0)
    };
    let lin = |seed: f64| {
        let mut lin = Linearization::new(n, m, p);
        lin.a.fill(0.0);
        lin.a.view_mut((0, 0), (2, 3)).copy_from(&dense(2, 3, seed));
        for j in 3..n {
            lin.a[(j - 1, j)] = 1.0;
        }
        lin.b.fill(0.0);
        lin.b[(n - 1, 0)] = 1.0;
        lin.b.view_mut((0, 1), (2, 1)).copy_from(&dense(2, 1, seed));
        for (cx, cu) in lin.cx.iter_mut().zip(&mut lin.cu) {
            cx.fill(0.0);
            cx.view_mut((0, 0), (2, 3)).copy_from(&dense(2, 3, -seed));
            cu.fill(0.0);
        }
        lin.noise = NoiseKind::Dependent;
        lin
    };
    let mut support = StateSupport::with_capacity(n, m);
    for j in 0..n {
        support.a.push(if j < 3 {
            Column::Rows(0..2)
        } else {
            Column::Unit(j - 1)
        });
        support.cx.push(if j < 3 { 0..2 } else { 0..0 });
    }
    support.b = vec![Column::Unit(n - 1), Column::Rows(0..2)];
    support.cu = vec![0..0; m];
    let mut sp = SparseLinearization::new(n, m, p);
    sp.make_room(Some(&support));
    let room = |sp: &SparseLinearization| {
        let each = |c: &SparseColumns| c.row.capacity().min(c.val.capacity());
        let mut all = vec![each(&sp.a), each(&sp.b)];
        all.extend(sp.cx.iter().chain(&sp.cu).map(each));
        all
    };
    let (allowed, whole) = ([9, 3, 6, 6, 0, 0], [36, 12, 36, 36, 12, 12]);
    for ((r, a), w) in room(&sp).into_iter().zip(allowed).zip(whole) {
        assert!(a <= r && r < w, "room {r} for {a} nonzeros of {w}");
    }
    let places = |sp: &SparseLinearization| {
        let mut all = vec![sp.a.row.as_ptr(), sp.b.row.as_ptr()];
        all.extend(sp.cx.iter().map(|c| c.row.as_ptr()));
        all
    };
    let before = places(&sp);
    for seed in [1.0, 2.0] {
        sp.assign(&lin(seed), Some(&support));
        let nnz: Vec<usize> = [&sp.a, &sp.b, &sp.cx[0]].iter().map(|c| c.nnz()).collect();
        assert_eq!(nnz, [9, 3, 6], "seed {seed}");
        assert_eq!(
            places(&sp),
            before,
            "seed {seed}: the refill moved the storage"
        );
    }
    let mut full = SparseLinearization::new(n, m, p);
    full.make_room(None);
    for (r, w) in room(&full).into_iter().zip(whole) {
        assert!(r >= w, "room {r} for {w} entries");
    }
}

/// Skipping the empty columns outside the occupied ones changes no bit of `y += α Mᵀ v`,
/// `out += α Mᵀ X` and `out += α Mᵀ (S N)` (outputs holding zeros of both signs, factors of
/// both signs and zero), against every column visited; nor for a matrix with no nonzero.
#[test]
fn skipping_empty_columns_changes_no_bit() {
    let (n, c) = (6, 9);
    for (seed, occupied) in [(1, 2..5), (2, 0..0), (3, 0..9), (4, 8..9)] {
        let mut m = pattern(n, c, seed);
        for j in (0..c).filter(|j| !occupied.contains(j)) {
            m.column_mut(j).fill(0.0);
        }
        let mut sp = SparseColumns::new(n, c);
        sp.assign(&m);
        let v: Vec<f64> = pattern(n, 1, seed + 10).iter().copied().collect();
        let x = pattern(n, 3, seed + 20);
        let s = {
            let a = pattern(n, n, seed + 30);
            &a + a.transpose()
        };
        let other = {
            let mut o = SparseColumns::new(n, 2);
            o.assign(&pattern(n, 2, seed + 40));
            o
        };
        for alpha in [1.0, 0.5, 0.0, -0.0, -1.0] {
            let start: Vec<f64> = (0..c).map(|j| [0.0, -0.0, 1.5][j % 3]).collect();
            let (mut y, mut want) = (start.clone(), start.clone());
            sp.tr_mul_vec_add(alpha, &v, &mut y);
            for (j, w) in want.iter_mut().enumerate() {
                let (rows, vals) = sp.column(j);
                let dot: f64 = rows.iter().zip(vals).map(|(&i, &a)| a * v[i]).sum();
                *w += alpha * dot;
            }
            let bits = |y: &[f64]| y.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&y), bits(&want), "Mᵀ v, seed {seed}, α {alpha}");
            let dirty = DMatrix::from_fn(c, 3, |i, j| [0.0, -0.0, 2.0][(i + j) % 3]);
            let (mut out, mut want) = (dirty.clone(), dirty.clone());
            sp.tr_mul_add(alpha, &x, &mut out);
            for q in 0..3 {
                for j in 0..c {
                    let (rows, vals) = sp.column(j);
                    let dot: f64 = rows.iter().zip(vals).map(|(&i, &a)| a * x[(i, q)]).sum();
                    want[(j, q)] += alpha * dot;
                }
            }
            assert_eq!(
                bits(out.as_slice()),
                bits(want.as_slice()),
                "Mᵀ X, α {alpha}"
            );
            let dirty = DMatrix::from_fn(c, 2, |i, j| [0.0, -0.0, 2.0][(i + j) % 3]);
            let (mut out, mut want) = (dirty.clone(), dirty.clone());
            let mut rows = Vec::new();
            sp.tr_mul_product_add(alpha, &s, &other, &mut rows, &mut out);
            let mut sn = DMatrix::zeros(n, 2);
            other.right_mul(&s, &mut sn);
            for q in 0..2 {
                for j in 0..c {
                    let (idx, vals) = sp.column(j);
                    let dot: f64 = idx.iter().zip(vals).map(|(&i, &a)| a * sn[(i, q)]).sum();
                    want[(j, q)] += alpha * dot;
                }
            }
            assert_eq!(
                bits(out.as_slice()),
                bits(want.as_slice()),
                "Mᵀ S N, α {alpha}"
            );
        }
    }
}
