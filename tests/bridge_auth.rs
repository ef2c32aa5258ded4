//! Who may join the link. With default settings (mutual TLS, `--keys` from `vic bridge keygen`)
//! a foreign Zenoh peer — plain TCP, TLS with another pair's keys, TLS trusting the pair's
//! authority but without a certificate — neither reads the board's state, nor drives it, nor
//! moves the bridge's clock estimate by answering its probes, while the paired bridges link.
//! The same foreign peer against a `--insecure-plain-tcp` bridge does all three (so the
//! refusal above is the keys' doing), and the CLI refuses plain TCP off loopback and keys that
//! others can read.

#![cfg(feature = "zenoh")]

use crate::common;

use common::bridge::{bridge, keygen, keys, port, stop_bridge, wait_for};
use common::daemons::{Daemons, unique_namespace};
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use vic_rt::bridge::clock::Responder;
use vic_rt::bridge::key;
use vic_rt::bridge::wire::encode;
use vic_rt::transport::{CommandSlice, Control, Header};
use zenoh::Wait;

/// The clock skew the foreign peer claims when it answers the probes.
const FOREIGN_SKEW_NS: i64 = 10_000_000_000;

/// How a foreign peer dials the board-side bridge.
enum Dial<'a> {
    /// Plain TCP.
    Plain,
    /// TLS with this key directory's `central` certificate and key, trusting its `ca.pem`.
    Keys(&'a Path),
    /// TLS trusting this `ca.pem`, presenting no certificate.
    CaOnly(&'a Path),
}

/// A foreign peer: a Zenoh session dialling `endpoint` (retrying all along), subscribed to
/// everything on the link (counting what it did not put itself), answering the clock probes 10 s ahead, and putting commands and
/// resets until dropped.
struct Foreign {
    session: zenoh::Session,
    samples: Arc<AtomicU64>,
    responder: Responder,
    _all: zenoh::pubsub::Subscriber<()>,
}

impl Foreign {
    fn dial(endpoint: &str, dial: Dial, link: &str) -> Foreign {
        let mut c = zenoh::Config::default();
        let mut set = |k: &str, v: String| c.insert_json5(k, &v).unwrap();
        set("connect/endpoints", format!(r#"["{endpoint}"]"#));
        set("connect/timeout_ms", "-1".into());
        set("connect/exit_on_failure", "false".into());
        set("scouting/multicast/enabled", "false".into());
        let tls = "transport/link/tls";
        let s = |p: std::path::PathBuf| format!("{:?}", p.to_string_lossy());
        match dial {
            Dial::Plain => {}
            Dial::Keys(dir) => {
                set(&format!("{tls}/root_ca_certificate"), s(dir.join("ca.pem")));
                set(
                    &format!("{tls}/connect_certificate"),
                    s(dir.join("central.pem")),
                );
                set(
                    &format!("{tls}/connect_private_key"),
                    s(dir.join("central.key")),
                );
                set(&format!("{tls}/enable_mtls"), "true".into());
            }
            Dial::CaOnly(dir) => {
                set(&format!("{tls}/root_ca_certificate"), s(dir.join("ca.pem")));
            }
        }
        let session = zenoh::open(c).wait().unwrap();
        let samples = Arc::new(AtomicU64::new(0));
        let all = session
            .declare_subscriber(format!("vic/{link}/**"))
            .callback({
                let samples = samples.clone();
                // Not its own puts (Zenoh delivers those to local subscribers too).
                let own = [key::<CommandSlice>(link), key::<Control>(link)];
                move |sample| {
                    if !own.iter().any(|k| k == sample.key_expr().as_str()) {
                        samples.fetch_add(1, Ordering::Relaxed);
                    }
                }
            })
            .wait()
            .unwrap();
        let responder = Responder::start(&session, link, FOREIGN_SKEW_NS).unwrap();
        Foreign {
            session,
            samples,
            responder,
            _all: all,
        }
    }

    /// Puts a command slice and a reset on the link.
    fn drive(&self, link: &str, seq: u64) {
        let command = CommandSlice {
            header: Header::new(seq, 1),
            ..Default::default()
        };
        let control = Control {
            header: Header::new(seq, 1),
            ..Default::default()
        };
        let s = &self.session;
        s.put(key::<CommandSlice>(link), encode(&command).to_vec())
            .wait()
            .unwrap();
        s.put(key::<Control>(link), encode(&control).to_vec())
            .wait()
            .unwrap();
    }

    fn peers(&self) -> usize {
        self.session.info().peers_zid().wait().count()
    }

    fn samples(&self) -> u64 {
        self.samples.load(Ordering::Relaxed)
    }
}

/// Lets the foreign peers drive for `d`.
fn drive_for(peers: &[&Foreign], link: &str, d: Duration, seq: &mut u64) {
    let t0 = Instant::now();
    while t0.elapsed() < d {
        for p in peers {
            p.drive(link, *seq);
        }
        *seq += 1;
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_foreign_peer_can_neither_read_nor_drive_nor_skew_the_clock_of_a_paired_link() {
    let (host_a, host_b) = (unique_namespace("aua"), unique_namespace("aub"));
    let link = unique_namespace("aul");
    let endpoint = format!("tls/127.0.0.1:{}", port(8));
    let plain = format!("tcp/127.0.0.1:{}", port(8));
    let other_pair = keygen("other");
    let mut d = Daemons::default();
    d.board(&host_a, &[]);
    let board_side = bridge(
        &mut d,
        "board",
        &host_a,
        &link,
        ["--listen", &endpoint],
        &[],
    );
    // The foreign peers dial first, so that theirs would be the first clock answers.
    let foreign = [
        Foreign::dial(&plain, Dial::Plain, &link),
        Foreign::dial(&endpoint, Dial::Keys(&other_pair), &link),
        Foreign::dial(&endpoint, Dial::CaOnly(keys()), &link),
    ];
    let peers: Vec<&Foreign> = foreign.iter().collect();
    let mut seq = 1;
    drive_for(&peers, &link, Duration::from_secs(1), &mut seq);
    // The paired bridge links all the same, and the board's state crosses to host B.
    bridge(
        &mut d,
        "central",
        &host_b,
        &link,
        ["--connect", &endpoint],
        &[],
    );
    assert!(
        wait_for(&host_b, Duration::from_secs(10), |s| s["tick"]
            .as_u64()
            .is_some_and(|t| t > 100)),
        "the paired bridges did not link"
    );
    drive_for(&peers, &link, Duration::from_secs(1), &mut seq);

    for (i, f) in foreign.iter().enumerate() {
        assert_eq!(f.peers(), 0, "foreign peer {i} joined the link");
        assert_eq!(f.samples(), 0, "foreign peer {i} read the link");
        assert_eq!(
            f.responder.stats().probes_answered,
            0,
            "foreign peer {i} saw the clock probes"
        );
    }
    let stats = stop_bridge(&mut d, board_side);
    let s = &stats["stats"];
    eprintln!("board side: {s}");
    assert_eq!(s["received"]["command"], 0, "a foreign command arrived");
    assert_eq!(s["received"]["control"], 0, "a foreign reset arrived");
    let offset = s["clock"]["offset_ns"].as_i64().expect("an offset");
    // One machine: the real offset is 0 (± the round trip); the foreign answers claim −10 s.
    assert!(
        offset.abs() < 50_000_000,
        "clock estimate moved to {offset} ns"
    );
    assert!(s["clock"]["answers"].as_u64().unwrap() > 0);
    drop(foreign);
    let _ = std::fs::remove_dir_all(other_pair);
}

/// The control experiment: the same foreign peer against a plain-TCP bridge reads its state,
/// drives it and moves its clock estimate by the 10 s it claims.
#[test]
fn the_same_foreign_peer_reads_drives_and_skews_a_plain_tcp_bridge() {
    let host_a = unique_namespace("apa");
    let link = unique_namespace("apl");
    let endpoint = format!("tcp/127.0.0.1:{}", port(9));
    let mut d = Daemons::default();
    d.board(&host_a, &[]);
    let board_side = bridge(
        &mut d,
        "board",
        &host_a,
        &link,
        ["--listen", &endpoint],
        &[],
    );
    let f = Foreign::dial(&endpoint, Dial::Plain, &link);
    let mut seq = 1;
    let t0 = Instant::now();
    while f.samples() < 100 && t0.elapsed() < Duration::from_secs(10) {
        drive_for(&[&f], &link, Duration::from_millis(100), &mut seq);
    }
    assert_eq!(f.peers(), 1);
    assert!(f.samples() >= 100, "the foreign peer read nothing");
    let stats = stop_bridge(&mut d, board_side);
    let s = &stats["stats"];
    eprintln!("board side: {s}");
    assert!(s["received"]["command"].as_u64().unwrap() > 0);
    assert!(s["received"]["control"].as_u64().unwrap() > 0);
    let offset = s["clock"]["offset_ns"].as_i64().expect("an offset");
    assert!(
        (offset + FOREIGN_SKEW_NS).abs() < 50_000_000,
        "offset {offset} ns, the foreign peer claimed −{FOREIGN_SKEW_NS} ns"
    );
}

/// `vic bridge` with `args` (a board side in a namespace that is never opened): its exit code
/// and stderr.
fn refused(args: &[&str]) -> (Option<i32>, String) {
    let ns = unique_namespace("aur");
    let out = Command::new(env!("CARGO_BIN_EXE_vic"))
        .args([
            "bridge",
            "--side",
            "board",
            "--namespace",
            &ns,
            "--duration-s",
            "1",
        ])
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn plain_tcp_off_loopback_missing_keys_and_readable_keys_are_refused() {
    let keys = keys().to_string_lossy().into_owned();
    let p = port(10);
    let any = format!("tcp/0.0.0.0:{p}");
    let lan = format!("tcp/192.168.1.20:{p}");
    let lo = format!("tcp/127.0.0.1:{p}");
    let tls = format!("tls/127.0.0.1:{p}");
    for (args, says) in [
        (vec!["--listen", &any, "--insecure-plain-tcp"], "loopback"),
        (vec!["--connect", &lan, "--insecure-plain-tcp"], "loopback"),
        (vec!["--listen", &lo], "--keys"),
        (vec!["--listen", &lo, "--keys", &keys], "tls/"),
        (vec!["--listen", &tls, "--insecure-plain-tcp"], "--keys"),
        (
            vec!["--listen", "udp/127.0.0.1:7447", "--keys", &keys],
            "protocol",
        ),
        (
            vec!["--listen", "tls/127.0.0.1:7447#iface=lo", "--keys", &keys],
            "#",
        ),
    ] {
        let (code, err) = refused(&args);
        assert_eq!(code, Some(2), "{args:?} was not refused as input: {err}");
        assert!(
            err.contains(says),
            "{args:?}: the error does not say {says}: {err}"
        );
    }

    // The files keygen wrote are owner-only; a private key others can read is refused, and
    // keygen never overwrites keys.
    let dir = keygen("modes");
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode(&dir), 0o700);
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "board.key",
            "board.pem",
            "ca.pem",
            "central.key",
            "central.pem"
        ]
    );
    for n in &names {
        assert_eq!(mode(&dir.join(n)), 0o600, "{n}");
        let text = std::fs::read_to_string(dir.join(n)).unwrap();
        assert_eq!(text.contains("PRIVATE KEY"), n.ends_with(".key"), "{n}");
    }
    let key = dir.join("board.key");
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o640)).unwrap();
    let d = dir.to_string_lossy().into_owned();
    let (code, err) = refused(&["--listen", &tls, "--keys", &d]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("board.key") && err.contains("owner only"),
        "{err}"
    );
    let again = Command::new(env!("CARGO_BIN_EXE_vic"))
        .args(["bridge", "keygen", "--out", &d])
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(2));
    assert_eq!(mode(&key), 0o640, "keygen touched the old key");
    let _ = std::fs::remove_dir_all(dir);
}
