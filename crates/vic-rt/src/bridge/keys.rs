//! The keys of one pair of bridges: a private certificate authority that signs exactly two
//! certificates, one per side, and is then forgotten (its private key is never written), so no
//! third certificate it trusts can ever exist. Each bridge presents its own certificate and
//! accepts only a peer whose certificate that authority signed (mutual TLS): a Zenoh peer
//! without one of the two keys fails the handshake and never sees a message.
//!
//! A key directory ([`generate`]) holds `ca.pem` (the authority's certificate) and
//! `board.pem`/`board.key`, `central.pem`/`central.key`; each host needs `ca.pem` and its own
//! side's pair ([`KeyFiles::of`]). The files are written owner-only (0600, the directory 0700)
//! and a bridge refuses a key file that others can read.

use super::Side;
use std::fs;
use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// The names under which a listening bridge is always reachable on its own machine.
pub const LOOPBACK_NAMES: [&str; 3] = ["localhost", "127.0.0.1", "::1"];

/// Why keys could not be made or used.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    #[error("{path}: {what}")]
    File { path: PathBuf, what: String },
    #[error("--name {0:?}: use a host name or an IP address (1–253 characters of [A-Za-z0-9.:-])")]
    Name(String),
    #[error("making the certificates: {0}")]
    Certificate(String),
}

fn file_error(path: &Path, what: impl std::fmt::Display) -> KeyError {
    KeyError::File {
        path: path.to_path_buf(),
        what: what.to_string(),
    }
}

fn side_name(side: Side) -> &'static str {
    match side {
        Side::Board => "board",
        Side::Central => "central",
    }
}

/// The files one bridge needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyFiles {
    /// The pair's certificate authority: the only one a peer's certificate may come from.
    pub ca: PathBuf,
    /// This side's certificate and private key.
    pub certificate: PathBuf,
    pub private_key: PathBuf,
}

impl KeyFiles {
    /// The files of `side` in key directory `dir`, checked: present, regular files, and the
    /// private key readable by its owner only.
    pub fn of(dir: &Path, side: Side) -> Result<Self, KeyError> {
        let name = side_name(side);
        let files = KeyFiles {
            ca: dir.join("ca.pem"),
            certificate: dir.join(format!("{name}.pem")),
            private_key: dir.join(format!("{name}.key")),
        };
        for path in [&files.ca, &files.certificate, &files.private_key] {
            let meta = fs::metadata(path).map_err(|e| {
                file_error(
                    path,
                    format!("{e} (make the keys with `vic bridge keygen`)"),
                )
            })?;
            if !meta.is_file() || meta.len() > 64 * 1024 {
                return Err(file_error(
                    path,
                    "not a key file (a regular file under 64 KiB)",
                ));
            }
        }
        let meta = fs::metadata(&files.private_key).map_err(|e| file_error(dir, e))?;
        if meta.mode() & 0o077 != 0 {
            return Err(file_error(
                &files.private_key,
                format!(
                    "mode {:o}: a private key must be readable by its owner only (chmod 600)",
                    meta.mode() & 0o777
                ),
            ));
        }
        Ok(files)
    }
}

fn check_name(name: &str) -> Result<(), KeyError> {
    let ok = |c: char| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | ':');
    if name.is_empty() || name.len() > 253 || !name.chars().all(ok) {
        return Err(KeyError::Name(name.to_string()));
    }
    Ok(())
}

/// Makes a new pair's keys in `dir` (created 0700 if absent; existing key files are never
/// overwritten). `names`: the host names and addresses under which a listening bridge is
/// reached (the connecting one checks the listener's certificate against the name it dialled);
/// [`LOOPBACK_NAMES`] are always included. Returns the files written.
pub fn generate(dir: &Path, names: &[String]) -> Result<Vec<PathBuf>, KeyError> {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose,
        IsCa, KeyPair, KeyUsagePurpose,
    };
    for n in names {
        check_name(n)?;
    }
    let mut sans: Vec<String> = LOOPBACK_NAMES.iter().map(|s| s.to_string()).collect();
    for n in names {
        if !sans.contains(n) {
            sans.push(n.clone());
        }
    }
    let cert_error = |e: rcgen::Error| KeyError::Certificate(e.to_string());

    let mut ca = CertificateParams::new(Vec::<String>::new()).map_err(cert_error)?;
    ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca.distinguished_name
        .push(DnType::CommonName, "vic bridge pair authority");
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign];
    let ca = CertifiedIssuer::self_signed(ca, KeyPair::generate().map_err(cert_error)?)
        .map_err(cert_error)?;

    let mut out = vec![(PathBuf::from("ca.pem"), ca.pem())];
    for side in [Side::Board, Side::Central] {
        let name = side_name(side);
        let mut p = CertificateParams::new(sans.clone()).map_err(cert_error)?;
        p.distinguished_name
            .push(DnType::CommonName, format!("vic bridge {name}"));
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        p.use_authority_key_identifier_extension = true;
        let key = KeyPair::generate().map_err(cert_error)?;
        let cert = p.signed_by(&key, &*ca).map_err(cert_error)?;
        out.push((format!("{name}.pem").into(), cert.pem()));
        out.push((format!("{name}.key").into(), key.serialize_pem()));
    }

    fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
        .map_err(|e| file_error(dir, e))?;
    for (name, _) in &out {
        let path = dir.join(name);
        if fs::symlink_metadata(&path).is_ok() {
            return Err(file_error(
                &path,
                "exists; keys are never overwritten (choose another --out or remove the old keys)",
            ));
        }
    }
    let mut written = Vec::new();
    for (name, text) in out {
        let path = dir.join(name);
        let mut f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(&path)
            .map_err(|e| file_error(&path, e))?;
        f.write_all(text.as_bytes())
            .and_then(|()| f.sync_all())
            .map_err(|e| file_error(&path, e))?;
        written.push(path);
    }
    Ok(written)
}
