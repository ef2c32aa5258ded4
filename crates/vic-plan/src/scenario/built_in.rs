//! The scenarios of `config/`, compiled in: an installed `vic` (`cargo install --path .`) run
//! from any folder finds `config/NAME.toml` although no such file is there. A file on disk always
//! wins; the built-in copy is read only when the relative path `config/NAME.toml` names no file.

use crate::bounded_read::{MAX_SCENARIO_BYTES, read_text_at_most};
use std::path::Path;

/// `(file name, text)` of every scenario in `config/`.
const BUILT_IN: [(&str, &str); 12] = [
    (
        "icub_elbow.toml",
        include_str!("../../../../config/icub_elbow.toml"),
    ),
    (
        "icub_experiment.toml",
        include_str!("../../../../config/icub_experiment.toml"),
    ),
    (
        "single_joint_delay.toml",
        include_str!("../../../../config/single_joint_delay.toml"),
    ),
    (
        "two_link_curl.toml",
        include_str!("../../../../config/two_link_curl.toml"),
    ),
    (
        "two_link_deterministic.toml",
        include_str!("../../../../config/two_link_deterministic.toml"),
    ),
    (
        "two_link_divergent.toml",
        include_str!("../../../../config/two_link_divergent.toml"),
    ),
    (
        "two_link_divergent_fast_vsa.toml",
        include_str!("../../../../config/two_link_divergent_fast_vsa.toml"),
    ),
    (
        "two_link_divergent_maccepa.toml",
        include_str!("../../../../config/two_link_divergent_maccepa.toml"),
    ),
    (
        "two_link_reach.toml",
        include_str!("../../../../config/two_link_reach.toml"),
    ),
    (
        "two_link_torque_divergent.toml",
        include_str!("../../../../config/two_link_torque_divergent.toml"),
    ),
    (
        "two_link_vsa_divergent.toml",
        include_str!("../../../../config/two_link_vsa_divergent.toml"),
    ),
    (
        "two_link_vsa_light_divergent.toml",
        include_str!("../../../../config/two_link_vsa_light_divergent.toml"),
    ),
];

/// The text of the scenario at `path`: the file, or, when `path` is `config/NAME.toml`, names no
/// file and `NAME.toml` is a scenario of `config/`, the built-in copy. A file larger than
/// [`MAX_SCENARIO_BYTES`] is refused after reading that much.
pub fn read(path: &Path) -> std::io::Result<String> {
    read_text_at_most(path, MAX_SCENARIO_BYTES, "scenario file")
        .or_else(|e| built_in(path).map(str::to_string).ok_or(e))
}

/// The built-in copy of `path` when it stands for one (see [`read`]); `None` when the file exists.
fn built_in(path: &Path) -> Option<&'static str> {
    if path.exists() || path.parent() != Some(Path::new("config")) {
        return None;
    }
    let name = path.file_name()?.to_str()?;
    BUILT_IN
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
}

/// Whether `path` names a scenario: a file, or a built-in one (see [`read`]).
pub fn exists(path: &Path) -> bool {
    path.is_file() || built_in(path).is_some()
}

/// Whether `dir` is a folder of scenarios: a folder, or `config` where none is (the built-in
/// scenarios then stand in for it).
pub fn is_folder(dir: &Path) -> bool {
    dir.is_dir() || (dir == Path::new("config") && !dir.exists())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every built-in copy is the file in `config/` byte for byte, and every file there is built
    /// in (a scenario added to `config/` without a line here fails).
    #[test]
    fn the_built_in_scenarios_are_the_files_of_config() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
        let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".toml"))
            .collect();
        on_disk.sort();
        let built: Vec<&str> = BUILT_IN.iter().map(|(n, _)| *n).collect();
        assert_eq!(on_disk, built);
        for (name, text) in BUILT_IN {
            assert_eq!(
                std::fs::read_to_string(dir.join(name)).unwrap(),
                text,
                "{name}"
            );
        }
    }

    /// From a folder without `config/` (the unit tests run in the crate's folder),
    /// `config/NAME.toml` reads the built-in copy; any other missing path stays an error.
    #[test]
    fn a_missing_config_path_falls_back_only_for_built_in_names() {
        assert!(
            !Path::new("config").exists(),
            "run from a folder without config/"
        );
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/icub_elbow.toml");
        let text = read(Path::new("config/icub_elbow.toml")).unwrap();
        assert_eq!(text, std::fs::read_to_string(file).unwrap());
        assert!(exists(Path::new("config/icub_elbow.toml")));
        for missing in [
            "config/no_such_scenario.toml",
            "other/icub_elbow.toml",
            "icub_elbow.toml",
        ] {
            let e = read(Path::new(missing)).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::NotFound, "{missing}");
            assert!(!exists(Path::new(missing)), "{missing}");
        }
        assert!(is_folder(Path::new("config")) && !is_folder(Path::new("configs")));
    }
}
