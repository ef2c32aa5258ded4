//! The library's layers import only downwards (core → planning → rt → tools) and no two modules
//! import each other, read off the source text: every `crate::layer::module` path a file names
//! (imports, paths in code and in doc links alike) is an edge from its module to that module.
//! And no source file grows past [`MAX_FILE_LINES`] lines.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const LAYERS: [&str; 4] = ["core", "planning", "rt", "tools"];

/// Module → (its layer, the modules it names, its file).
type Graph = BTreeMap<String, (usize, BTreeSet<(usize, String)>, PathBuf)>;

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

/// `layer::module` of a file below `src/` (`core::solver` for `src/core/solver/ilqg.rs`).
fn module_of(src: &Path, file: &Path) -> Option<(usize, String)> {
    let rel = file.strip_prefix(src).ok()?;
    let parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    let layer = LAYERS.iter().position(|l| *l == parts[0])?;
    let module = parts.get(1).filter(|m| *m != "mod")?;
    Some((layer, format!("{}::{}", parts[0], module)))
}

/// Every `crate::layer::module` named in `text`.
fn references(text: &str) -> BTreeSet<(usize, String)> {
    let mut out = BTreeSet::new();
    for (i, _) in text.match_indices("crate::") {
        let rest = &text[i + "crate::".len()..];
        let path: Vec<&str> = rest
            .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
            .next()
            .unwrap_or("")
            .split("::")
            .collect();
        if let Some(layer) = LAYERS.iter().position(|l| *l == path[0])
            && let Some(module) = path.get(1).filter(|m| !m.is_empty())
        {
            out.insert((layer, format!("{}::{}", path[0], module)));
        }
    }
    out
}

fn graph() -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut g: Graph = BTreeMap::new();
    for file in files {
        let Some((layer, module)) = module_of(&src, &file) else {
            continue;
        };
        let text = std::fs::read_to_string(&file).expect("readable source file");
        let entry = g
            .entry(module.clone())
            .or_insert_with(|| (layer, BTreeSet::new(), file.clone()));
        entry
            .1
            .extend(references(&text).into_iter().filter(|(_, m)| *m != module));
    }
    g
}

#[test]
fn layers_import_only_downwards() {
    let mut upward = Vec::new();
    for (module, (layer, refs, file)) in graph() {
        for (to_layer, to) in refs {
            if to_layer > layer {
                upward.push(format!("{module} ({}) uses {to}", file.display()));
            }
        }
    }
    assert!(
        upward.is_empty(),
        "imports up the layers:\n{}",
        upward.join("\n")
    );
}

#[test]
fn the_real_time_layer_does_not_know_planning() {
    let offenders: Vec<String> = graph()
        .into_iter()
        .filter(|(_, (layer, _, _))| LAYERS[*layer] == "rt")
        .flat_map(|(m, (_, refs, _))| {
            refs.into_iter()
                .filter(|(l, _)| LAYERS[*l] == "planning")
                .map(move |(_, to)| format!("{m} uses {to}"))
        })
        .collect();
    assert!(offenders.is_empty(), "{}", offenders.join("\n"));
}

#[test]
fn no_two_modules_depend_on_each_other_in_a_cycle() {
    let g = graph();
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
        for (_, next) in g.get(m).map(|e| e.1.clone()).unwrap_or_default() {
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
            visit(m, &g, &mut colour, &mut Vec::new(), &mut cycles);
        }
    }
    assert!(cycles.is_empty(), "import cycles:\n{}", cycles.join("\n"));
}

#[test]
fn the_checker_sees_an_upward_import() {
    let refs = references("use crate::rt::board::Board;\nlet x = crate::core::policy::Policy;");
    assert!(refs.contains(&(2, "rt::board".into())));
    assert!(refs.contains(&(0, "core::policy".into())));
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
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    rust_files(&root.join("bins"), &mut files);
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
