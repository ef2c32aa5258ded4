//! `docs/CONFIG.md` against the schema: every key the loader accepts is documented under its
//! section (and variant), every documented key is one the loader accepts, the documented values of
//! a key with a fixed set of values are that set, and the documented defaults and `[board]` ranges
//! are the code's.
//!
//! The schema is asked of the loader itself: an unknown key `section.bogus_key` is refused with
//! serde's list of the keys it expected, an unknown value `section.key=zz_bogus` of an enum key
//! with the list of its variants. The sections and the keys that select a variant come from
//! `sections.rs`.

use super::board::RawBoard;
use super::raw::RawSolver;
use super::sections::{SECTIONS, tag_of};
use super::{BOARD_RANGES, Scenario};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use vic_core::solver::IlqgOptions;
use vic_core::solver::sooc_newton::SoocOptions;

const DOC: &str = include_str!("../../../../docs/CONFIG.md");

/// A valid scenario that leaves every optional `[task]`, `[solver]` and `[board]` key at its
/// default (but the hold stiffness, which the default makes unstable on this forearm): the loader
/// tests' elbow.
const BASE: &str = super::tests::ELBOW;

const BOGUS_KEY: &str = "bogus_key";
const BOGUS_VALUE: &str = "zz_bogus";

fn load(overrides: &[String]) -> Result<Scenario, super::ConfigError> {
    Scenario::from_str(BASE, Path::new("base.toml"), overrides)
}

/// The backquoted names after "expected" in a serde message (`expected one of `a`, `b``,
/// `expected `a` or `b``, `expected `a``); none for "there are no fields".
fn expected_names(message: &str) -> BTreeSet<String> {
    if message.contains("there are no fields") {
        return BTreeSet::new();
    }
    let rest = message
        .split_once("expected")
        .unwrap_or_else(|| panic!("no list of expected names in: {message}"))
        .1;
    backquoted(rest).into_iter().collect()
}

/// Every `name` between backquotes in `text`, in order.
fn backquoted(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// The message of the error the loader gives for `overrides` on [`BASE`].
fn refusal(overrides: &[String]) -> String {
    match load(overrides) {
        Ok(_) => panic!("{overrides:?} accepted"),
        Err(e) => e.to_string(),
    }
}

/// The keys the loader accepts in `section` (with `tag = variant` for a tagged section), the tag
/// key itself not included (the loader takes it off before serde reads the section).
fn schema_keys(section: &str, variant: Option<&str>) -> BTreeSet<String> {
    let mut overrides = Vec::new();
    if let (Some(tag), Some(v)) = (tag_of(section), variant) {
        overrides.push(format!("{section}.{tag}={v}"));
    }
    overrides.push(format!("{section}.{BOGUS_KEY}=1"));
    let e = refusal(&overrides);
    assert!(
        e.contains(&format!("unknown field `{BOGUS_KEY}`")),
        "{overrides:?}: not refused as an unknown key: {e}"
    );
    expected_names(&e)
}

/// The values the loader accepts for `section.key` when it is an enum (`None`: the key takes no
/// string, or any).
fn enum_values(section: &str, variant: Option<&str>, key: &str) -> Option<BTreeSet<String>> {
    let mut overrides = Vec::new();
    if let (Some(tag), Some(v)) = (tag_of(section), variant)
        && tag != key
    {
        overrides.push(format!("{section}.{tag}={v}"));
    }
    overrides.push(format!("{section}.{key}={BOGUS_VALUE}"));
    let e = load(&overrides).err()?.to_string();
    e.contains(&format!("unknown variant `{BOGUS_VALUE}`"))
        .then(|| expected_names(&e))
}

/// One row of a key table: its key and its cells (key, unit, default, range, meaning).
#[derive(Debug)]
struct Row {
    key: String,
    cells: Vec<String>,
}

/// `(section, variant)` → the rows documented there, in order. Rows directly under `## [section]`
/// have no variant; those under `### tag = "variant"` have that variant.
type Documented = BTreeMap<(String, Option<String>), Vec<Row>>;

fn documented() -> Documented {
    let mut doc = Documented::new();
    let mut at: Option<(String, Option<String>)> = None;
    for (n, line) in DOC.lines().enumerate() {
        let n = n + 1;
        if let Some(h) = line.strip_prefix("## ") {
            at = h
                .strip_prefix('[')
                .and_then(|h| h.strip_suffix(']'))
                .map(|s| (s.to_string(), None));
            if let Some(key) = &at {
                assert!(
                    doc.insert(key.clone(), Vec::new()).is_none(),
                    "line {n}: section documented twice: {line}"
                );
            }
        } else if let Some(h) = line.strip_prefix("### ") {
            let Some((section, _)) = &at else {
                continue;
            };
            let tag = tag_of(section)
                .unwrap_or_else(|| panic!("line {n}: [{section}] has no variants: {line}"));
            let variant = h
                .strip_prefix(&format!("{tag} = \""))
                .and_then(|v| v.strip_suffix('"'))
                .unwrap_or_else(|| panic!("line {n}: expected ### {tag} = \"variant\": {line}"));
            let key = (section.clone(), Some(variant.to_string()));
            assert!(
                doc.insert(key.clone(), Vec::new()).is_none(),
                "line {n}: variant documented twice: {line}"
            );
            at = Some(key);
        } else if line.starts_with("| `") {
            let Some(key) = &at else {
                panic!("line {n}: a key row outside a section: {line}");
            };
            let cells: Vec<String> = line
                .trim()
                .trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_string())
                .collect();
            assert_eq!(cells.len(), 5, "line {n}: expected 5 cells: {line}");
            let name = backquoted(&cells[0]);
            assert!(
                name.len() == 1 && cells[0] == format!("`{}`", name[0]),
                "line {n}: the first cell must be one `key`: {line}"
            );
            let rows = doc.get_mut(key).expect("inserted at its heading");
            assert!(
                rows.iter().all(|r| r.key != name[0]),
                "line {n}: key documented twice in {key:?}: {line}"
            );
            rows.push(Row {
                key: name[0].clone(),
                cells,
            });
        }
    }
    doc
}

fn keys(rows: &[Row]) -> BTreeSet<String> {
    rows.iter().map(|r| r.key.clone()).collect()
}

/// Missing (in the schema, not in the doc) and stale (in the doc, not in the schema) keys of one
/// place, as a complaint, if any.
fn compare(place: &str, schema: &BTreeSet<String>, doc: &BTreeSet<String>) -> Option<String> {
    let missing: Vec<_> = schema.difference(doc).collect();
    let stale: Vec<_> = doc.difference(schema).collect();
    (!missing.is_empty() || !stale.is_empty())
        .then(|| format!("{place}: undocumented {missing:?}, stale {stale:?}"))
}

/// Every key of every section and variant, with the variants and the sections themselves, the
/// tag keys included; returns `(sections, variants, keys)` covered.
fn check_keys(doc: &Documented) -> (usize, usize, usize) {
    let mut faults = Vec::new();
    let documented_sections: BTreeSet<&str> = doc.keys().map(|(s, _)| s.as_str()).collect();
    let sections: BTreeSet<&str> = SECTIONS.into_iter().collect();
    if documented_sections != sections {
        faults.push(format!(
            "sections: documented {documented_sections:?}, schema {sections:?}"
        ));
    }
    let (mut variants, mut total) = (0, 0);
    for section in SECTIONS {
        let top = doc
            .get(&(section.to_string(), None))
            .map_or_else(BTreeSet::new, |rows| keys(rows));
        match tag_of(section) {
            None => {
                let schema = schema_keys(section, None);
                total += schema.len();
                faults.extend(compare(&format!("[{section}]"), &schema, &top));
            }
            Some(tag) => {
                // The tag key alone is documented at the section's top.
                let tag_set = BTreeSet::from([tag.to_string()]);
                faults.extend(compare(&format!("[{section}] (top)"), &tag_set, &top));
                total += 1;
                let schema_variants = enum_values(section, None, tag)
                    .unwrap_or_else(|| panic!("[{section}] {tag}: no list of variants"));
                let doc_variants: BTreeSet<String> = doc
                    .keys()
                    .filter(|(s, _)| s == section)
                    .filter_map(|(_, v)| v.clone())
                    .collect();
                faults.extend(compare(
                    &format!("[{section}] variants"),
                    &schema_variants,
                    &doc_variants,
                ));
                for variant in &schema_variants {
                    variants += 1;
                    let schema = schema_keys(section, Some(variant));
                    total += schema.len();
                    let documented = doc
                        .get(&(section.to_string(), Some(variant.clone())))
                        .map_or_else(BTreeSet::new, |rows| keys(rows));
                    faults.extend(compare(
                        &format!("[{section}] {tag} = \"{variant}\""),
                        &schema,
                        &documented,
                    ));
                }
            }
        }
    }
    assert!(faults.is_empty(), "docs/CONFIG.md:\n{}", faults.join("\n"));
    (SECTIONS.len(), variants, total)
}

#[test]
fn config_md_documents_every_key_and_no_other() {
    let doc = documented();
    let (sections, variants, keys) = check_keys(&doc);
    // Eight sections, four of them tagged with 2 + 3 + 3 + 3 variants.
    assert_eq!((sections, variants), (8, 11));
    assert!(keys > 60, "{keys} keys");
}

/// A key with a fixed set of values (`task.integrator`, `solver.method`, a tag key, ...) lists
/// exactly those values, backquoted, in its range column.
#[test]
fn config_md_lists_the_values_of_every_enum_key() {
    let mut faults = Vec::new();
    let mut checked = 0;
    for ((section, variant), rows) in documented() {
        for row in rows {
            let Some(values) = enum_values(&section, variant.as_deref(), &row.key) else {
                continue;
            };
            checked += 1;
            let listed: BTreeSet<String> = backquoted(&row.cells[3]).into_iter().collect();
            faults.extend(compare(
                &format!("[{section}] {} ({variant:?}) values", row.key),
                &values,
                &listed,
            ));
        }
    }
    assert!(faults.is_empty(), "docs/CONFIG.md:\n{}", faults.join("\n"));
    // The four tags, task.kind, task.integrator, actuator.damping,
    // actuator.stiffness_dynamics, solver.method and solver.indefinite.
    assert_eq!(checked, 10);
}

/// The row of `section.key` (of `variant` in a tagged section).
fn row<'a>(doc: &'a Documented, section: &str, variant: Option<&str>, key: &str) -> &'a Row {
    doc.get(&(section.to_string(), variant.map(str::to_string)))
        .and_then(|rows| rows.iter().find(|r| r.key == key))
        .unwrap_or_else(|| panic!("[{section}] {key} ({variant:?}) not documented"))
}

/// The documented default of `section.key`: its first word, backquotes off.
fn default_of(doc: &Documented, section: &str, variant: Option<&str>, key: &str) -> String {
    let cell = &row(doc, section, variant, key).cells[2];
    cell.split_whitespace()
        .next()
        .unwrap_or_default()
        .trim_matches('`')
        .to_string()
}

#[test]
fn config_md_states_the_codes_defaults_and_board_ranges() {
    let doc = documented();
    let number = |section: &str, variant: Option<&str>, key: &str| -> f64 {
        let d = default_of(&doc, section, variant, key);
        d.parse()
            .unwrap_or_else(|_| panic!("[{section}] {key}: default {d:?} is not a number"))
    };
    let boolean = |section: &str, key: &str| -> bool {
        let d = default_of(&doc, section, None, key);
        d.parse()
            .unwrap_or_else(|_| panic!("[{section}] {key}: default {d:?} is not a boolean"))
    };
    let b = RawBoard::default();
    for (key, value) in [
        ("watchdog", b.watchdog),
        ("ramp", b.ramp),
        ("hold_stiffness", b.hold_stiffness),
        ("velocity_max", b.velocity_max),
        ("future_tolerance", b.future_tolerance),
        ("max_pulse_torque", b.max_pulse_torque),
        ("max_load_torque", b.max_load_torque),
        ("max_pulse_duration", b.max_pulse_duration),
        ("max_field_beta", b.max_field_beta),
        ("max_noise_factor", b.max_noise_factor),
    ] {
        assert_eq!(number("board", None, key), value, "[board] {key} default");
    }
    for r in BOARD_RANGES {
        let open = if r.min_inclusive { '[' } else { '(' };
        let range = format!("{open}{}, {}]", r.min, r.max);
        let documented = row(&doc, "board", None, r.key);
        assert!(
            documented.cells[3].starts_with(&range),
            "[board] {}: range {range} in the code, {:?} documented",
            r.key,
            documented.cells[3]
        );
        assert_eq!(documented.cells[1], r.unit, "[board] {} unit", r.key);
    }
    let ilqg = IlqgOptions::default();
    let sooc = SoocOptions::default();
    assert_eq!(
        number("solver", None, "max_iterations"),
        ilqg.max_iterations as f64
    );
    assert_eq!(number("solver", None, "tolerance"), ilqg.tolerance);
    assert_eq!(
        number("solver", None, "gradient_tolerance"),
        ilqg.gradient_tolerance
    );
    assert_eq!(number("solver", None, "mu_init"), ilqg.mu_init);
    assert_eq!(number("solver", None, "mu_min"), ilqg.mu_min);
    assert_eq!(number("solver", None, "mu_max"), ilqg.mu_max);
    assert_eq!(boolean("solver", "stochastic"), ilqg.stochastic);
    assert_eq!(boolean("solver", "damp_short_steps"), ilqg.damp_short_steps);
    assert_eq!(
        number("solver", None, "third_derivatives_below"),
        sooc.third_derivatives_below
    );
    assert_eq!(
        boolean("solver", "keep_third_derivatives"),
        sooc.keep_third_derivatives
    );
    assert_eq!(
        boolean("solver", "hold_stiffness_first"),
        RawSolver::default().hold_stiffness_first()
    );
    // What a scenario that leaves them out gets.
    let s = load(&[]).expect("the base scenario is valid");
    assert_eq!(number("task", None, "substeps"), s.task.substeps as f64);
    assert_eq!(number("task", None, "delay_ms"), s.task.delay_ms);
    assert_eq!(
        serde_json::to_value(s.task.integrator).unwrap(),
        default_of(&doc, "task", None, "integrator").as_str()
    );
    assert_eq!(
        default_of(&doc, "solver", None, "method"),
        s.solver.method.name()
    );
    assert_eq!(
        default_of(&doc, "solver", None, "indefinite"),
        serde_json::to_value(sooc.indefinite).unwrap()
    );
    let impedance = Some("impedance");
    assert_eq!(
        number("actuator", impedance, "stiffness_min"),
        s.bounds.lower[1]
    );
    assert_eq!(
        number("actuator", impedance, "initial_stiffness"),
        s.initial_stiffness
    );
    assert_eq!(number("plant", Some("single_joint"), "viscosity"), 0.0);
    // A VSA's first guess has a spring.
    let vsa = load(&[
        "actuator.type=vsa".to_string(),
        "actuator.motor_inertia=[2.0]".to_string(),
    ])
    .expect("the base scenario with a VSA is valid");
    assert_eq!(
        number("actuator", Some("vsa"), "initial_stiffness"),
        vsa.initial_stiffness
    );
}
