//! Nothing panics on any document: thousands of seeded mutations of real URDF files (truncation,
//! byte flips, numbers replaced by NaN, ±∞, 1e300, −1, 0, tags and names damaged) each give a
//! chain or a typed error, and a chain that is built evaluates its dynamics without panicking.

use super::tests::config;
use super::*;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

const REPLACEMENTS: [&str; 9] = ["NaN", "inf", "-inf", "1e300", "-1e300", "-1", "0", "", "x"];

/// One random mutation of `text`.
fn mutate(text: &str, rng: &mut StdRng) -> String {
    let bytes = text.as_bytes();
    match rng.random_range(0..6) {
        0 => String::from_utf8_lossy(&bytes[..rng.random_range(0..bytes.len())]).into_owned(),
        1 => {
            let mut b = bytes.to_vec();
            for _ in 0..rng.random_range(1..6) {
                let i = rng.random_range(0..b.len());
                b[i] = rng.random();
            }
            String::from_utf8_lossy(&b).into_owned()
        }
        2 | 3 => {
            // Replace some numbers (a maximal run of digits, '.', '-', 'e').
            let mut out = String::with_capacity(text.len());
            let mut chars = text.char_indices().peekable();
            while let Some((_, ch)) = chars.next() {
                if ch.is_ascii_digit() && rng.random_bool(0.02) {
                    while chars
                        .peek()
                        .is_some_and(|(_, c)| c.is_ascii_digit() || matches!(c, '.' | 'e' | '-'))
                    {
                        chars.next();
                    }
                    out.push_str(REPLACEMENTS[rng.random_range(0..REPLACEMENTS.len())]);
                } else {
                    out.push(ch);
                }
            }
            out
        }
        4 => {
            // Damage a tag or a name: swap joint types, drop a closing tag, rename a link.
            let swaps = [
                ("revolute", "prismatic"),
                ("fixed", "floating"),
                ("revolute", "continuous"),
                ("</link>", ""),
                ("</joint>", ""),
                ("<inertial>", "<inertia>"),
                ("child link=\"", "child link=\"x"),
                ("parent link=\"", "parent link=\"x"),
                ("<mass value=\"", "<mass value=\"-"),
            ];
            let (from, to) = swaps[rng.random_range(0..swaps.len())];
            let hits: Vec<usize> = text.match_indices(from).map(|(i, _)| i).collect();
            if hits.is_empty() {
                return text.to_string();
            }
            let at = hits[rng.random_range(0..hits.len())];
            format!("{}{to}{}", &text[..at], &text[at + from.len()..])
        }
        _ => {
            // Duplicate a random slice somewhere else.
            let (a, b) = (
                rng.random_range(0..bytes.len()),
                rng.random_range(0..bytes.len()),
            );
            let (lo, hi) = (a.min(b), a.max(b).min(a.min(b) + 400));
            let at = rng.random_range(0..bytes.len());
            let mut v = bytes[..at].to_vec();
            v.extend_from_slice(&bytes[lo..hi]);
            v.extend_from_slice(&bytes[at..]);
            String::from_utf8_lossy(&v).into_owned()
        }
    }
}

#[test]
fn no_mutated_document_makes_the_reader_or_the_dynamics_panic() {
    let files = [
        ("panda.urdf", "panda_link0", "panda_hand"),
        ("two_link.urdf", "torso", "hand"),
        ("single_joint.urdf", "upper_arm", "hand"),
        ("icub.urdf", "chest", "r_hand"),
    ];
    let mut rng = StdRng::seed_from_u64(2026);
    let (mut ok, mut refused) = (0, 0);
    let cases = 1500;
    for (file, base, tip) in files {
        let text = config(file);
        for case in 0..cases {
            let mut doc = mutate(&text, &mut rng);
            if rng.random_bool(0.3) {
                doc = mutate(&doc, &mut rng);
            }
            let result = std::panic::catch_unwind(|| {
                let chain = SerialChain::from_urdf_str(&doc, base, tip)?;
                let q = [0.3; MAX_DOF];
                let n = chain.dof();
                let _ = chain.forward_dynamics(&q[..n], &q[..n], &q[..n]);
                let _ = chain.tip_position(&q[..n]);
                Ok::<_, UrdfError>(n)
            });
            match result {
                Ok(Ok(n)) => {
                    assert!((1..=MAX_DOF).contains(&n));
                    ok += 1;
                }
                Ok(Err(e)) => {
                    assert_eq!(e.file, "<string>");
                    assert!(!e.element.is_empty() && !e.to_string().is_empty());
                    refused += 1;
                }
                Err(_) => panic!("{file}, case {case}: a panic on the document:\n{doc}"),
            }
        }
    }
    // Both outcomes occur: the mutations reach the checks and leave some documents usable.
    assert!(ok > 100 && refused > 1000, "{ok} built, {refused} refused");
}
