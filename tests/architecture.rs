//! The house's rules, read off the tree: the layer crates depend only downwards (vic-core →
//! vic-plan, vic-rt → the application; the compiler then refuses an upward import), the
//! mathematics depends on no I/O crate, no two modules of a crate import each other in a cycle
//! (every `crate::module` path a file names is an edge), and no source file grows past
//! [`MAX_FILE_LINES`] lines.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Each layer crate and the vic crates it may depend on.
const LAYERS: [(&str, &[&str]); 3] = [
    ("vic-core", &[]),
    ("vic-plan", &["vic-core"]),
    ("vic-rt", &["vic-core"]),
];

/// Crates that do I/O, draw, parse flags or talk to other processes: none of them is a dependency
/// of the mathematics.
const IO_CRATES: [&str; 14] = [
    "iceoryx2",
    "plotters",
    "clap",
    "mcap",
    "zenoh",
    "toml",
    "serde_json",
    "anyhow",
    "indicatif",
    "tracing",
    "libc",
    "ratatui",
    "hdrhistogram",
    "ctrlc",
];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The names of the `[dependencies]` of a crate's manifest.
fn dependencies(manifest: &Path) -> BTreeSet<String> {
    let text = std::fs::read_to_string(manifest).expect("readable manifest");
    let doc: toml::Table = toml::from_str(&text).expect("manifest is TOML");
    doc.get("dependencies")
        .and_then(|d| d.as_table())
        .map(|t| t.keys().cloned().collect())
        .unwrap_or_default()
}

#[test]
fn the_layer_crates_depend_only_downwards() {
    let mut wrong = Vec::new();
    for (name, allowed) in LAYERS {
        let deps = dependencies(&root().join("crates").join(name).join("Cargo.toml"));
        for dep in deps.iter().filter(|d| d.starts_with("vic")) {
            if !allowed.contains(&dep.as_str()) {
                wrong.push(format!("{name} depends on {dep}"));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "upward or sideways layer dependencies:\n{}",
        wrong.join("\n")
    );
    // The check can fail: the application depends on every layer.
    let app = dependencies(&root().join("Cargo.toml"));
    assert!(LAYERS.iter().all(|(n, _)| app.contains(*n)), "{app:?}");
}

#[test]
fn the_mathematics_and_the_planner_do_no_io_of_their_own() {
    for (name, io_allowed) in [
        ("vic-core", &[][..]),
        ("vic-plan", &["toml", "serde_json"][..]),
    ] {
        let deps = dependencies(&root().join("crates").join(name).join("Cargo.toml"));
        let io: Vec<_> = IO_CRATES
            .iter()
            .filter(|c| deps.contains(**c) && !io_allowed.contains(*c))
            .collect();
        assert!(io.is_empty(), "{name} depends on {io:?}");
    }
    let rt = dependencies(&root().join("crates/vic-rt/Cargo.toml"));
    assert!(
        rt.contains("iceoryx2"),
        "the check reads the manifests: {rt:?}"
    );
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable source directory") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Module → (the modules it names, its file).
type Graph = BTreeMap<String, (BTreeSet<String>, PathBuf)>;

/// The top-level module of a file below a crate's `src/` (`solver` for `src/solver/ilqg.rs`).
fn module_of(src: &Path, file: &Path) -> Option<String> {
    let first = file.strip_prefix(src).ok()?.iter().next()?;
    let m = first.to_string_lossy().trim_end_matches(".rs").to_string();
    (m != "lib" && m != "main").then_some(m)
}

/// Every top-level module named by a `crate::module` path in `text`.
fn references(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (i, _) in text.match_indices("crate::") {
        if i > 0 && text[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let rest = &text[i + "crate::".len()..];
        let m: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if !m.is_empty() {
            out.insert(m);
        }
    }
    out
}

fn graph(src: &Path) -> Graph {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut g: Graph = BTreeMap::new();
    for file in files {
        let Some(module) = module_of(src, &file) else {
            continue;
        };
        let text = std::fs::read_to_string(&file).expect("readable source file");
        let entry = g
            .entry(module.clone())
            .or_insert_with(|| (BTreeSet::new(), file.clone()));
        entry
            .0
            .extend(references(&text).into_iter().filter(|m| *m != module));
    }
    g
}

/// Every crate's `src/`: the layers', the application's and the Python bindings'.
fn source_dirs() -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = LAYERS
        .iter()
        .map(|(n, _)| root().join("crates").join(n).join("src"))
        .collect();
    dirs.push(root().join("src"));
    dirs.push(root().join("crates/vic-py/src"));
    dirs
}

#[test]
fn no_two_modules_depend_on_each_other_in_a_cycle() {
    for src in source_dirs() {
        let cycles = cycles(&graph(&src));
        assert!(
            cycles.is_empty(),
            "import cycles in {}:\n{}",
            src.display(),
            cycles.join("\n")
        );
    }
}

fn cycles(g: &Graph) -> Vec<String> {
    // Depth-first search with colours: grey = on the stack; a grey successor closes a cycle.
    fn visit(
        m: &str,
        g: &Graph,
        colour: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
        cycles: &mut Vec<String>,
    ) {
        colour.insert(m.to_string(), 1);
        stack.push(m.to_string());
        for next in g.get(m).map(|e| e.0.clone()).unwrap_or_default() {
            match colour.get(&next).copied().unwrap_or(0) {
                0 => visit(&next, g, colour, stack, cycles),
                1 => {
                    let start = stack.iter().position(|s| *s == next).unwrap_or(0);
                    cycles.push(format!("{} -> {next}", stack[start..].join(" -> ")));
                }
                _ => {}
            }
        }
        stack.pop();
        colour.insert(m.to_string(), 2);
    }
    let mut colour = BTreeMap::new();
    let mut cycles = Vec::new();
    for m in g.keys() {
        if colour.get(m).copied().unwrap_or(0) == 0 {
            visit(m, g, &mut colour, &mut Vec::new(), &mut cycles);
        }
    }
    cycles
}

#[test]
fn the_checker_sees_a_cycle() {
    let refs = references("use crate::board::Board;\nlet x = vic_core::policy::Policy;");
    assert_eq!(refs, BTreeSet::from(["board".to_string()]));
    let mut g = Graph::new();
    g.insert(
        "a".into(),
        (BTreeSet::from(["b".to_string()]), PathBuf::new()),
    );
    g.insert(
        "b".into(),
        (BTreeSet::from(["a".to_string()]), PathBuf::new()),
    );
    assert_eq!(cycles(&g).len(), 1);
}

/// Longest `.rs` file allowed under `src/` and `bins/`: a file longer than this holds more than
/// one concern and is split (the aim is ~600 lines; 650 leaves room for a fix in passing).
const MAX_FILE_LINES: usize = 650;

/// The `.rs` files among `files` longer than `max` lines, with their lengths.
fn too_long(files: &[PathBuf], max: usize) -> Vec<(usize, PathBuf)> {
    files
        .iter()
        .filter_map(|f| {
            let lines = std::fs::read_to_string(f)
                .expect("readable file")
                .lines()
                .count();
            (lines > max).then(|| (lines, f.clone()))
        })
        .collect()
}

#[test]
fn no_source_file_is_longer_than_the_limit() {
    let mut files = Vec::new();
    for src in source_dirs() {
        rust_files(&src, &mut files);
    }
    rust_files(&root().join("bins"), &mut files);
    assert!(
        files.len() > 50,
        "the walk found only {} files",
        files.len()
    );
    let long = too_long(&files, MAX_FILE_LINES);
    assert!(
        long.is_empty(),
        "files over {MAX_FILE_LINES} lines (split them by concern):\n{}",
        long.iter()
            .map(|(n, f)| format!("  {}: {n} lines", f.display()))
            .collect::<Vec<_>>()
            .join("\n")
    );
    // The check can fail: the longest file is over a limit just below its length.
    let (longest, _) = files
        .iter()
        .map(|f| (std::fs::read_to_string(f).unwrap().lines().count(), f))
        .max()
        .expect("files");
    assert!(
        too_long(&files, longest - 1)
            .iter()
            .any(|(n, _)| *n == longest)
    );
}
