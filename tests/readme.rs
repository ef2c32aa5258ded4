//! The command synopses of README.md and docs/GUIDE.md against the binaries' own `--help`: every
//! `--flag` a synopsis in a code block writes for `vic …`, `vic-board` or `vic-planner` is one
//! that command's help lists, so the docs cannot drift from the command line.

use std::process::Command;

/// The binary of a synopsis' first word.
fn binary(name: &str) -> Option<&'static str> {
    match name {
        "vic" => Some(env!("CARGO_BIN_EXE_vic")),
        "vic-board" => Some(env!("CARGO_BIN_EXE_vic-board")),
        "vic-planner" => Some(env!("CARGO_BIN_EXE_vic-planner")),
        _ => None,
    }
}

/// The `--help` of the longest prefix of `path` that is a command.
fn help(bin: &str, path: &[&str]) -> String {
    for k in (0..=path.len()).rev() {
        let out = Command::new(bin)
            .args(&path[..k])
            .arg("--help")
            .output()
            .unwrap();
        if out.status.success() {
            return String::from_utf8(out.stdout).unwrap();
        }
    }
    panic!("{bin} --help fails");
}

/// The leading words of `words` that look like subcommand names.
fn subcommands<'a>(words: &[&'a str]) -> Vec<&'a str> {
    words
        .iter()
        .take_while(|w| {
            !w.starts_with('-')
                && !w.is_empty()
                && w.chars().all(|c| c.is_ascii_lowercase() || c == '-')
        })
        .copied()
        .collect()
}

fn flags(text: &str) -> Vec<String> {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
        .filter(|w| w.starts_with("--") && w.len() > 2)
        .map(str::to_string)
        .collect()
}

#[test]
fn every_flag_of_the_readmes_synopses_is_in_its_commands_help() {
    // The README gives the two commands; the guide every synopsis.
    let readme = [
        include_str!("../README.md"),
        include_str!("../docs/GUIDE.md"),
    ]
    .join("\n");
    let mut in_block = false;
    let (mut checked, mut wrong) = (0, Vec::new());
    for line in readme.lines() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        let command = line.split(" # ").next().unwrap_or("").trim();
        let words: Vec<&str> = command.split_whitespace().collect();
        let Some(bin) = words.first().and_then(|w| binary(w)) else {
            continue;
        };
        if !in_block {
            continue;
        }
        // `vic inject pulse … | load … | field …`: alternatives of the last subcommand.
        let mut segments = command.split(" | ");
        let first: Vec<&str> = segments.next().unwrap().split_whitespace().collect();
        let path = subcommands(&first[1..]);
        let mut cases = vec![(path.clone(), first.join(" "))];
        for alt in segments {
            let alt_words: Vec<&str> = alt.split_whitespace().collect();
            let mut alt_path = path[..path.len().saturating_sub(1)].to_vec();
            alt_path.extend(subcommands(&alt_words));
            cases.push((alt_path, alt.to_string()));
        }
        for (path, text) in cases {
            let help = help(bin, &path);
            for flag in flags(&text) {
                checked += 1;
                if !help.contains(&flag) {
                    wrong.push(format!("{} {}: {flag}", words[0], path.join(" ")));
                }
            }
        }
    }
    assert!(
        checked > 30,
        "only {checked} flags found: is the README's format the same?"
    );
    assert!(wrong.is_empty(), "README flags not in --help: {wrong:?}");
}
