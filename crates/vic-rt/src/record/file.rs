//! Where a recording goes: a new file that never replaces an existing one unless asked to and
//! never follows a symbolic link, and the wording of a write error (a full disk is named).

use super::error::RecordError;
use std::fs::{File, OpenOptions};
use std::io;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// Creates `path` as a new file (`O_CREAT | O_EXCL | O_NOFOLLOW`, mode 0644 before the umask).
/// An existing entry is an error ([`RecordError::Exists`]) unless `replace`; with `replace` the
/// entry itself is removed first (a symbolic link is removed, not followed), a directory never.
pub fn create_new(path: &Path, replace: bool) -> Result<File, RecordError> {
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        let kind = kind_of(&meta);
        if meta.is_dir() || !replace {
            return Err(RecordError::Exists {
                path: path.to_path_buf(),
                kind,
                replaceable: !meta.is_dir(),
            });
        }
        std::fs::remove_file(path).map_err(|e| RecordError::io(path, e))?;
    }
    open_excl(path).map_err(|e| match e.kind() {
        // Created by someone else between the check and the open.
        io::ErrorKind::AlreadyExists => RecordError::Exists {
            path: path.to_path_buf(),
            kind: "an entry",
            replaceable: true,
        },
        _ => RecordError::io(path, e),
    })
}

fn open_excl(path: &Path) -> io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .mode(0o644)
        .open(path)
}

fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a file"
    } else {
        "a special file"
    }
}

/// A recording written under a temporary name next to its final one until it is known to be
/// wanted (`vic record` once the board's first state arrived): an existing file at the final
/// name is untouched by a recording that never starts (a mistyped namespace).
pub struct Placement {
    temp: PathBuf,
    out: PathBuf,
    replace: bool,
    placed: bool,
}

impl Placement {
    /// Checks `out` (an existing entry is refused unless `replace`) and creates the temporary
    /// file `.<name>.<pid>.part` in the same directory (`O_EXCL`, never a link).
    pub fn create(out: &Path, replace: bool) -> Result<(Placement, File), RecordError> {
        if let Ok(meta) = std::fs::symlink_metadata(out)
            && (meta.is_dir() || !replace)
        {
            return Err(RecordError::Exists {
                path: out.to_path_buf(),
                kind: kind_of(&meta),
                replaceable: !meta.is_dir(),
            });
        }
        let name = out
            .file_name()
            .ok_or_else(|| RecordError::format(out, "not a file name (it ends in `..` or `/`)"))?;
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".{}.part", std::process::id()));
        let temp = out.with_file_name(temp_name);
        let file = open_excl(&temp).map_err(|e| RecordError::io(&temp, e))?;
        Ok((
            Placement {
                temp,
                out: out.to_path_buf(),
                replace,
                placed: false,
            },
            file,
        ))
    }

    /// Gives the temporary file its final name (the open file keeps being written): a rename
    /// with `replace` (an existing entry, a link included, is replaced, not followed), else a
    /// hard link that fails if the name was taken meanwhile.
    pub fn place(&mut self) -> Result<(), RecordError> {
        if self.placed {
            return Ok(());
        }
        if self.replace {
            std::fs::rename(&self.temp, &self.out).map_err(|e| RecordError::io(&self.out, e))?;
        } else {
            std::fs::hard_link(&self.temp, &self.out).map_err(|e| match e.kind() {
                io::ErrorKind::AlreadyExists => RecordError::Exists {
                    path: self.out.clone(),
                    kind: "an entry (created while waiting for the board)",
                    replaceable: true,
                },
                _ => RecordError::io(&self.out, e),
            })?;
            let _ = std::fs::remove_file(&self.temp);
        }
        self.placed = true;
        Ok(())
    }

    /// Where the recording is now.
    pub fn current(&self) -> &Path {
        if self.placed { &self.out } else { &self.temp }
    }
}

impl Drop for Placement {
    /// A recording that never got its name (no board, an error before the first state) is
    /// removed: the temporary file is ours.
    fn drop(&mut self) {
        if !self.placed {
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// A write error as the user needs it: a full disk or quota is named (`ENOSPC`, `EDQUOT`).
pub fn describe(e: &io::Error) -> String {
    match e.raw_os_error() {
        Some(libc::ENOSPC) => "no space left on device (ENOSPC)".into(),
        Some(libc::EDQUOT) => "disk quota exceeded (EDQUOT)".into(),
        _ => e.to_string(),
    }
}

/// The I/O error inside an MCAP error, if that is what it is.
pub(crate) fn io_of(e: &mcap::McapError) -> Option<&io::Error> {
    match e {
        mcap::McapError::Io(e) => Some(e),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("vic-record-file-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn an_existing_file_or_link_is_refused_and_left_alone() {
        let d = dir("exists");
        let (file, target, link) = (d.join("a.mcap"), d.join("target"), d.join("l.mcap"));
        std::fs::write(&file, b"keep").unwrap();
        std::fs::write(&target, b"victim").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        for p in [&file, &link] {
            let e = create_new(p, false).unwrap_err();
            assert!(matches!(e, RecordError::Exists { .. }), "{e}");
            assert!(e.to_string().contains("--force"), "{e}");
            let e = Placement::create(p, false).map(|_| ()).unwrap_err();
            assert!(matches!(e, RecordError::Exists { .. }), "{e}");
        }
        assert_eq!(std::fs::read(&file).unwrap(), b"keep");
        assert_eq!(std::fs::read(&target).unwrap(), b"victim");
        // Replacing a link replaces the link, not its target.
        drop(create_new(&link, true).unwrap());
        assert!(!std::fs::symlink_metadata(&link).unwrap().is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"victim");
        // A directory is never replaced.
        assert!(create_new(&d, true).is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_placement_that_never_places_leaves_nothing_and_one_that_does_keeps_writing() {
        use std::io::Write;
        let d = dir("place");
        let out = d.join("run.mcap");
        let (p, _f) = Placement::create(&out, false).unwrap();
        let temp = p.current().to_path_buf();
        assert!(temp.exists() && !out.exists());
        drop(p);
        assert!(!temp.exists() && !out.exists());
        let (mut p, mut f) = Placement::create(&out, false).unwrap();
        f.write_all(b"one ").unwrap();
        p.place().unwrap();
        f.write_all(b"two").unwrap();
        drop(p);
        assert_eq!(std::fs::read(&out).unwrap(), b"one two");
        assert_eq!(
            std::fs::read_dir(&d).unwrap().count(),
            1,
            "the temporary name is gone"
        );
        // Taken while waiting: refused, the other file untouched.
        std::fs::remove_file(&out).unwrap();
        let (mut p, _f) = Placement::create(&out, false).unwrap();
        std::fs::write(&out, b"theirs").unwrap();
        assert!(matches!(p.place(), Err(RecordError::Exists { .. })));
        assert_eq!(std::fs::read(&out).unwrap(), b"theirs");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
